"""Yarn tubes of ``--method bysdf`` (stages/core/yarn/tubes.py).

References: the spline itself, densely sampled (the polyline's distance from it, against the stated
bound of rel_err x radius); the rotation-minimising frame of ``stages.core.curves.frames`` evaluated
at the exact arc length (the frame a hit maps back to); a closed-form straight yarn.
"""
import math

import numpy as np
import pytest

from stages.core.curves.frames import curve_frame_at
from stages.core.curves.spline import segment_point
from stages.core.geometry.bvh import build_fiber_bvh, intersect
from stages.core.yarn.tubes import (
    cylinder_span,
    point_from_yarn,
    to_yarn,
    tube_pieces,
    yarn_hit_frame,
)
from stages.ingest.spline_process import curves_from_arrays, process_curves


def _curves(points_list, closed):
    pts = np.concatenate(points_list)
    off = np.concatenate([[0], np.cumsum([len(p) for p in points_list])]).astype(np.int64)
    rad = np.full(len(points_list), 0.05)
    cl = np.asarray(closed, bool)
    return curves_from_arrays(pts, off, cl, rad, process_curves(pts, off, cl, rad))


def _wavy_and_loop():
    x = np.linspace(0, 2, 13)
    wavy = np.stack([x, 0.1 * np.sin(6 * x), 0.05 * np.cos(9 * x)], axis=1)
    a = np.linspace(0, 2 * math.pi, 9)[:-1]
    loop = np.stack([1 + 0.3 * np.cos(a), 0.3 * np.sin(a), 0.1 * np.sin(2 * a)], axis=1)
    return _curves([wavy, loop], [False, True])


def _polyline_distance(P, q):
    a = P[:-1]
    b = P[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
    return np.min(np.linalg.norm(a + t[:, None] * ab - q, axis=1))


@pytest.mark.parametrize("rel_err", [0.01, 0.002])
def test_polyline_within_stated_bound_of_spline(rel_err):
    """Every point of the spline lies within rel_err x radius of its tube polyline (the module doc's
    bound h^2/8 max|P''|), and the bound is not vacuous (the worst deviation is a sizeable part of it)."""
    cv = _wavy_and_loop()
    R = np.array([0.05, 0.08])
    pc = tube_pieces(cv, R, rel_err)
    worst = 0.0
    for c in range(2):
        P = pc.points[pc.offsets[c]:pc.offsets[c + 1]]
        lo = cv.offsets[c]
        nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
        for i in range(lo, lo + nseg):
            for t in np.linspace(0, 1, 41):
                d = _polyline_distance(P, segment_point(cv, i, t))
                assert d <= rel_err * R[c] * (1 + 1e-9), (c, i, t, d)
                worst = max(worst, d / (rel_err * R[c]))
        if cv.closed[c]:
            assert np.allclose(P[0], P[-1])
    assert worst > 0.2


def test_hit_maps_to_the_rmf_frame_at_its_arc_length():
    """A ray hitting the tube at piece j maps to the frame ``curve_frame_at`` gives at the hit's arc length
    (within the polyline bound), with the hit at distance R from the axis in yarn space."""
    cv = _wavy_and_loop()
    R = 0.05
    pc = tube_pieces(cv, np.full(2, R), 0.01)
    bvh, _ = build_fiber_bvh(pc.points, pc.offsets, pc.radius)
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(300):
        target = pc.points[rng.integers(0, len(pc.points))]
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        o = target - 2.0 * d + rng.normal(scale=0.02, size=3)
        t, s = intersect(bvh, o[0], o[1], o[2], d[0], d[1], d[2], 1e-9, np.inf, -1, -1, 0)
        if s < 0:
            continue
        p = o + t * d
        fr = yarn_hit_frame(cv, pc, bvh.seg_a[s], p[0], p[1], p[2])
        pos, tan, n, b = curve_frame_at(cv, fr.curve, fr.s)
        assert np.allclose([fr.px, fr.py, fr.pz], pos, atol=1e-9)
        assert np.allclose([fr.nx, fr.ny, fr.nz], n, atol=1e-9)
        q, _ = to_yarn(fr, p[0], p[1], p[2], d[0], d[1], d[2])
        if not (1e-9 < fr.s < cv.curve_length[fr.curve] - 1e-9):
            continue   # an open yarn's end cap
        assert abs(math.hypot(q[0], q[1]) - R) < 0.011 * R       # on the tube (the polyline bound)
        assert abs(q[2] - fr.s) < 0.01 * R    # the closest point (within the piece's spline segment)
        assert np.allclose(point_from_yarn(fr, q), p, atol=1e-12)
        checked += 1
    assert checked > 100


def test_cylinder_span_closed_form():
    """Entry and exit of a straight cylinder: x^2 + y^2 = R^2 solved by hand."""
    o = np.array([-2.0, 0.3, 0.0])
    d = np.array([1.0, 0.0, 0.0])
    u0, u1 = cylinder_span(o, d, 0.5)
    assert u0 == pytest.approx(2.0 - 0.4) and u1 == pytest.approx(2.0 + 0.4)
    u0, u1 = cylinder_span(np.array([0.0, 0.6, 0.0]), d, 0.5)
    assert u0 > u1
    u0, u1 = cylinder_span(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.5)
    assert u0 == -np.inf and u1 == np.inf
