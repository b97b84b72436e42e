"""Yarn-curve kernels (stages/core/curves.py, stages/ingest/spline_process.py) against named references:
interpolation and C1 continuity (finite differences), the analytic RMF of a planar curve and of a helix,
brute-force projection over dense samples, the δ_i covering bound of seed 000 §5.2, and a brute-force
"which yarns within r" search."""
import math

import numpy as np
import pytest

from stages.core.curves.closest import closest_point_on_curve, yarns_near
from stages.core.curves.frames import curve_frame_at
from stages.core.curves.spline import curve_point_at, segment_point
from stages.core.curves.yarn_space import from_yarn_space, to_yarn_space
from stages.ingest.spline_process import curves_from_arrays, process_curves, sample_curve_points

R_HELIX, C_HELIX = 1.0, 0.25


def _build(curves, closed, radius=0.05):
    pts = np.concatenate(curves)
    off = np.concatenate([[0], np.cumsum([len(c) for c in curves])])
    closed = np.array(closed)
    rad = np.full(len(curves), radius)
    return curves_from_arrays(pts, off, closed, rad, process_curves(pts, off, closed, rad))


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 6 * np.pi, 121)
    helix = np.stack([R_HELIX * np.cos(t), R_HELIX * np.sin(t), C_HELIX * t], 1)
    u = np.linspace(0, 2 * np.pi, 41)[:-1]
    planar_loop = np.stack([1.5 * np.cos(u) + 3, np.sin(u) + 0.3 * np.sin(3 * u), np.zeros_like(u)], 1)
    wiggle = np.stack([np.linspace(-2, 2, 30), 0.2 * rng.normal(size=30), 0.2 * rng.normal(size=30)], 1)
    return _build([helix, planar_loop, wiggle], [False, True, False])


def test_spline_interpolates_and_is_c1(scene):
    cv = scene
    for i in range(cv.offsets[0], cv.offsets[1] - 1):
        assert np.allclose(segment_point(cv, i, 0.0), cv.points[i], atol=1e-12)
        assert np.allclose(segment_point(cv, i, 1.0), cv.points[i + 1], atol=1e-12)
    # C1: one-sided finite-difference derivatives agree across every joint (closed loop included)
    h = 1e-6
    for c in range(3):
        lo, hi = cv.offsets[c], cv.offsets[c + 1]
        last = hi - 1 if cv.closed[c] else hi - 2
        for i in range(lo, last):
            j = i + 1 if i + 1 < hi else lo
            left = (segment_point(cv, i, 1.0) - segment_point(cv, i, 1.0 - h)) / h
            right = (segment_point(cv, j, h) - segment_point(cv, j, 0.0)) / h
            assert np.allclose(left, right, atol=1e-4 * (1 + np.abs(left).max()))


def test_arc_length_of_helix_matches_closed_form(scene):
    L = scene.curve_length[0]
    exact = 6 * np.pi * math.sqrt(R_HELIX ** 2 + C_HELIX ** 2)
    assert abs(L - exact) / exact < 2e-4  # spline through 121 samples of the helix
    # arc-length parameterisation: |d alpha / ds| = 1
    for s in np.linspace(0.1, L - 0.1, 25):
        d = (curve_point_at(scene, 0, s + 1e-5) - curve_point_at(scene, 0, s - 1e-5)) / 2e-5
        assert abs(np.linalg.norm(d) - 1.0) < 1e-5


def test_frames_orthonormal_everywhere(scene):
    for c in range(3):
        for s in np.linspace(0, scene.curve_length[c], 97):
            p, t, n, b = curve_frame_at(scene, c, s)
            m = np.stack([t, n, b])
            assert np.allclose(m @ m.T, np.eye(3), atol=1e-10)
            assert np.allclose(np.cross(t, n), b, atol=1e-12)


def test_planar_curve_frame_is_plane_normal(scene):
    """Reference: the RMF of a planar curve started at the plane normal keeps the plane normal."""
    for s in np.linspace(0, scene.curve_length[1], 200):
        _, t, n, _ = curve_frame_at(scene, 1, s)
        assert abs(abs(n[2]) - 1.0) < 1e-9


def test_helix_frame_is_rotation_minimising(scene):
    """Reference: relative to the Frenet frame of a helix the RMF turns at minus the torsion,
    tau = c / (r^2 + c^2), per unit arc length."""
    L = scene.curve_length[0]
    speed = math.sqrt(R_HELIX ** 2 + C_HELIX ** 2)
    tau = C_HELIX / speed ** 2
    angles, ss = [], np.linspace(0.5, L - 0.5, 60)
    for s in ss:
        _, t, n, b = curve_frame_at(scene, 0, s)
        u = s / speed
        N = np.array([-math.cos(u), -math.sin(u), 0.0])  # Frenet normal of the helix
        angles.append(math.atan2(np.dot(np.cross(N, n), t), np.dot(N, n)))
    angles = np.unwrap(angles)
    slope = np.polyfit(ss, angles, 1)[0]
    assert abs(abs(slope) - tau) / tau < 2e-3
    # and no twist about the tangent: dn/ds . b == 0
    for s in ss[::6]:
        _, _, n0, b0 = curve_frame_at(scene, 0, s)
        _, _, n1, _ = curve_frame_at(scene, 0, s + 1e-4)
        assert abs(np.dot((n1 - n0) / 1e-4, b0)) < 2e-3


def test_projection_equals_dense_brute_force(scene):
    rng = np.random.default_rng(11)
    for c in range(3):
        dense = sample_curve_points(scene, c, 40001)
        L = scene.curve_length[c]
        lo, hi = dense.min(0) - 0.5, dense.max(0) + 0.5
        for p in rng.uniform(lo, hi, size=(40, 3)):
            s, d2 = closest_point_on_curve(scene, c, p)
            dd = np.sum((dense - p) ** 2, axis=1)
            k = int(np.argmin(dd))
            spacing = L / 40000
            # ours is a true minimum: never farther than any dense sample, and within the sampling error of it
            assert math.sqrt(d2) <= math.sqrt(dd[k]) + 1e-12
            assert math.sqrt(dd[k]) - math.sqrt(d2) <= spacing
            # the returned arc length s points at that closest point
            assert abs(np.linalg.norm(curve_point_at(scene, c, s) - p) - math.sqrt(d2)) < 1e-9


def test_yarn_space_round_trip(scene):
    rng = np.random.default_rng(5)
    for c in range(3):
        for _ in range(30):
            s = rng.uniform(0, scene.curve_length[c])
            x, y = rng.uniform(-0.04, 0.04, 2)
            p = from_yarn_space(scene, c, x, y, s)
            x2, y2, s2, d2 = to_yarn_space(scene, c, p)
            assert abs(x2 - x) < 1e-9 and abs(y2 - y) < 1e-9
            ds = abs(s2 - s)
            if scene.closed[c]:
                ds = min(ds, scene.curve_length[c] - ds)
            assert ds < 1e-9


def test_delta_bounds_vertex_minus_curve_distance(scene):
    """seed 000 §5.2: d1(p) - d2(p) <= δ_i for all p (d1 to control points, d2 to the curve)."""
    rng = np.random.default_rng(8)
    for c in range(3):
        verts = scene.points[scene.offsets[c]:scene.offsets[c + 1]]
        dense = sample_curve_points(scene, c, 20001)
        worst = 0.0
        for p in np.concatenate([rng.uniform(dense.min(0) - 0.3, dense.max(0) + 0.3, (300, 3)),
                                 dense[::97] + rng.normal(0, 0.01, (len(dense[::97]), 3))]):
            d1 = np.sqrt(np.min(np.sum((verts - p) ** 2, 1)))
            d2 = math.sqrt(closest_point_on_curve(scene, c, p)[1])
            worst = max(worst, d1 - d2)
        assert worst <= scene.delta[c] + 1e-12
        assert scene.delta[c] < 0.75 * np.max(np.linalg.norm(np.diff(verts, axis=0), axis=1))


def test_yarns_near_equals_brute_force(scene):
    rng = np.random.default_rng(2)
    out = np.empty(8, np.int32)
    dense = [sample_curve_points(scene, c, 20001) for c in range(3)]
    lo = np.min([d.min(0) for d in dense], axis=0) - 0.4
    hi = np.max([d.max(0) for d in dense], axis=0) + 0.4
    checked = 0
    for p in rng.uniform(lo, hi, size=(3000, 3)):
        got = set(out[: yarns_near(scene, p, 0.05, out)].tolist())
        exact = {c for c in range(3) if closest_point_on_curve(scene, c, p)[1] <= 0.05 ** 2}
        assert got == exact
        checked += bool(exact)
    assert checked > 5
