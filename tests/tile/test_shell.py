"""The shell (stages/tile/shell.py: build_shell), called directly on small base surfaces.

References: closed forms for a flat rectangle (the shell is the box width x height x T, its map to flat
space the scaling (x / width * flat_w, y / height * flat_h, z / T * flat_T)) and for a cylinder patch (the
shell's volume converges to the annular sector's (R+T)^2 - R^2)/2 x angle x length from below); outward
boundary normals by the tetrahedra's own vertices; brute-force face counts.
"""
import math

import numpy as np

from stages.tile.base_surfaces import cylinder, flat_rectangle, vertex_normals
from stages.tile.shell import build_shell


def test_flat_shell_is_a_scaled_box():
    """Reference: a flat 2 x 1 rectangle, T = 0.1, flat size 4 x 3, flat thickness 0.5: tetrahedron volumes
    sum to 2 x 1 x 0.1 and are positive; w2f is the scaling diag(2, 3, 5) everywhere; the boundary has
    2 triangles per base triangle (bottom, top) and 2 per boundary edge, all with outward normals."""
    V, UV, F = flat_rectangle(2.0, 1.0, 4, 3)
    N = vertex_normals(V, F)
    sh = build_shell(V, UV, F, N, 0.1, (4.0, 3.0), flat_thickness=0.5)
    assert np.all(sh["volume"] > 0)
    np.testing.assert_allclose(sh["volume"].sum(), 2.0 * 1.0 * 0.1, rtol=1e-12)
    S = np.diag([2.0, 3.0, 5.0])
    np.testing.assert_allclose(sh["w2f"][:, :, :3], np.broadcast_to(S, (len(sh["tets"]), 3, 3)), atol=1e-12)
    np.testing.assert_allclose(sh["w2f"][:, :, 3], 0.0, atol=1e-12)
    np.testing.assert_allclose(sh["flat"], sh["vertices"] @ S, atol=1e-12)
    assert len(sh["bnd_tet"]) == 2 * len(F) + 2 * 2 * (4 + 3)
    _check_outward(sh)


def _check_outward(sh):
    """Every boundary face: its triangle is the tetrahedron's face opposite bnd_face, and bnd_normal points
    away from the opposite vertex; every neighbour pair is symmetric."""
    X, tets = sh["vertices"], sh["tets"]
    for k, (t, f) in enumerate(zip(sh["bnd_tet"], sh["bnd_face"])):
        opp = X[tets[t, f]]
        tri = sh["bnd_tri"][k]
        np.testing.assert_allclose(np.sort(tri, axis=0), np.sort(X[np.delete(tets[t], f)], axis=0))
        assert (opp - tri.mean(axis=0)) @ sh["bnd_normal"][k] < 0
    nbr = sh["neighbours"]
    for t, i in zip(*np.nonzero(nbr >= 0)):
        assert t in nbr[nbr[t, i]]


def _enclosed_volume(sh):
    """Volume bounded by the boundary triangles (divergence theorem, oriented by bnd_normal)."""
    tri = sh["bnd_tri"]
    det = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    sign = np.sign(np.einsum("ij,ij->i", n, sh["bnd_normal"]))
    assert np.all(sign != 0)
    return float(np.sum(sign * det) / 6.0)


def test_cylinder_shell_volume():
    """Reference: a 120-degree cylinder patch of radius R = 1, length 0.5, T = 0.2, nu = 12 angular steps.
    With exactly radial normals the shell is a prism over the polygonal annulus sector: volume
    ((R+T)^2 - R^2) / 2 nu sin(step) x length (closed form). With the smoothed vertex normals, the
    tetrahedra fill exactly the volume the boundary triangles enclose (divergence theorem): no gap, no
    overlap. Every tetrahedron positive in both."""
    V, UV, F = cylinder(1.0, 0.5, 120.0, 12, 3)
    radial = V * [1.0, 0.0, 1.0]
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    sh = build_shell(V, UV, F, radial, 0.2, (1.0, 1.0))
    assert np.all(sh["volume"] > 0)
    exact = 0.5 * (1.2 ** 2 - 1.0) * 12 * math.sin(math.radians(10.0)) * 0.5
    np.testing.assert_allclose(sh["volume"].sum(), exact, rtol=1e-12)
    np.testing.assert_allclose(_enclosed_volume(sh), exact, rtol=1e-12)
    _check_outward(sh)
    sh = build_shell(V, UV, F, vertex_normals(V, F), 0.2, (1.0, 1.0))
    assert np.all(sh["volume"] > 0)
    np.testing.assert_allclose(sh["volume"].sum(), _enclosed_volume(sh), rtol=1e-12)
    _check_outward(sh)
