"""Base surfaces for shell mapping (stages/tile/base_surfaces.py), called directly.

References: closed forms (the rectangle's and cylinder's positions and normals; by the grid's point
symmetry an interior vertex normal of the cylinder is exactly radial), lengths kept along the radial lines
of the sphere drape (arc length on the sphere r = R theta, then straight down), and hand-broken meshes for
``triangle_checks`` (one triangle collapsed, one flipped).
"""
import math

import numpy as np
import pytest

from stages.tile.base_surfaces import (
    cylinder,
    face_normals,
    flat_rectangle,
    sphere_drape,
    triangle_checks,
    vertex_normals,
)


def _uv_area(UV, F):
    e1 = UV[F[:, 1]] - UV[F[:, 0]]
    e2 = UV[F[:, 2]] - UV[F[:, 0]]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


@pytest.mark.parametrize("surface", ["flat", "cylinder", "drape"])
def test_normals_are_unit_and_agree_with_the_winding(surface):
    """Contract: triangles counter-clockwise in (u, v) (uv area > 0, summing to 1), vertex normals unit,
    geometric normals on the side of the vertex normals; triangle_checks finds nothing wrong."""
    V, UV, F = {"flat": lambda: flat_rectangle(2.0, 1.0, 4, 3), "cylinder": lambda: cylinder(1.0, 2.0, 150.0, 12, 4),
                "drape": lambda: sphere_drape(4.0, 1.0, 16, 16, 6, 0.15)}[surface]()
    assert np.all(_uv_area(UV, F) > 0)
    assert _uv_area(UV, F).sum() == pytest.approx(1.0, rel=1e-12)
    N = vertex_normals(V, F)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, rtol=1e-12)
    fn = face_normals(V, F)
    for k in range(3):
        assert np.all(np.einsum("ij,ij->i", fn, N[F[:, k]]) > 0)
    deg, flip = triangle_checks(V, UV, F, N)
    assert len(deg) == 0 and len(flip) == 0


def test_closed_forms_of_rectangle_and_cylinder():
    """Reference: rectangle x = u w, y = v h, z = 0 with normals +z; cylinder (r sin phi, v L, r cos phi),
    phi = angle (u - 1/2), outward normals exactly radial at interior vertices (point symmetry of the fan)."""
    V, UV, F = flat_rectangle(2.0, 1.5, 4, 3)
    np.testing.assert_allclose(V, np.c_[UV * [2.0, 1.5], np.zeros(len(V))], atol=1e-15)
    np.testing.assert_allclose(vertex_normals(V, F), np.tile([0.0, 0.0, 1.0], (len(V), 1)), atol=1e-15)
    V, UV, F = cylinder(0.7, 2.0, 150.0, 12, 4)
    phi = math.radians(150.0) * (UV[:, 0] - 0.5)
    np.testing.assert_allclose(V, np.c_[0.7 * np.sin(phi), 2.0 * UV[:, 1], 0.7 * np.cos(phi)], atol=1e-15)
    N = vertex_normals(V, F)
    inner = (UV[:, 0] > 0) & (UV[:, 0] < 1) & (UV[:, 1] > 0) & (UV[:, 1] < 1)
    np.testing.assert_allclose(N[inner], np.c_[np.sin(phi), np.zeros(len(V)), np.cos(phi)][inner], atol=1e-12)


def test_sphere_drape_keeps_radial_lengths():
    """Reference: the drape's rule: a cloth point at distance r < pi R / 2 from the centre lies on the
    sphere at polar angle r / R; beyond, at height -(r - pi R / 2) below the equator; so along each radial
    line of the cloth (u = v diagonal and the u axis) consecutive vertices are as far apart on the surface
    as in the cloth, up to the chord-vs-arc error on the sphere."""
    size, R = 4.0, 1.0
    V, UV, F = sphere_drape(size, R, 32, 32, 6, 0.15)
    c = (UV - 0.5) * size
    r = np.hypot(c[:, 0], c[:, 1])
    on = r < 0.5 * math.pi * R
    np.testing.assert_allclose(np.linalg.norm(V[on], axis=1), R, rtol=1e-12)
    np.testing.assert_allclose(np.arccos(np.clip(V[on, 2] / R, -1, 1)), r[on] / R, atol=1e-12)
    hang = ~on
    np.testing.assert_allclose(V[hang, 2], -(r[hang] - 0.5 * math.pi * R), atol=1e-12)
    # along the u axis through the centre (v = 1/2, phi = 0 and pi: no fold offset, sin(6 phi) = 0)
    row = np.flatnonzero(np.isclose(UV[:, 1], 0.5))
    row = row[np.argsort(UV[row, 0])]
    d_cloth = np.diff(c[row, 0])
    d_surf = np.linalg.norm(np.diff(V[row], axis=0), axis=1)
    # a chord of an arc of length s on the sphere is 2 R sin(s / 2R); off the sphere it is exact
    assert np.all(d_surf <= d_cloth + 1e-12)
    np.testing.assert_allclose(d_surf, d_cloth, rtol=(d_cloth.max() / R) ** 2 / 24 + 1e-12)


def test_triangle_checks_flag_broken_triangles():
    """Reference: a hand-broken mesh: triangle 3 collapsed onto an edge (zero area), triangle 7 flipped
    (two vertices swapped: uv orientation and normal against the rest); each is reported in its list only."""
    V, UV, F = cylinder(1.0, 2.0, 150.0, 8, 4)
    N = vertex_normals(V, F)
    F = F.copy()
    F[3] = [F[3, 0], F[3, 1], F[3, 1]]
    F[7] = F[7, [0, 2, 1]]
    deg, flip = triangle_checks(V, UV, F, N)
    assert list(deg) == [3]
    assert list(flip) == [7]
    V2 = V.copy()
    a, b, c = F[11]
    V2[c] = 0.5 * (V2[a] + V2[b])  # collinear in 3-D, but still a proper triangle in uv
    deg, _ = triangle_checks(V2, UV, F, N)
    assert 11 in deg
