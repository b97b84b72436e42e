"""Full realization (stages/procedural/realize.py), called directly on a 2 x 2 plain weave with gentle crimp
(the yarn-space map does not fold; warp cotton1, weft polyester1 scaled to the yarn radius, 12 fibres per
ply; loops and hybrid hairs on).

References: the plan's own counts (yarn_counts == yarn_plan == realize_plan == what realize_fill writes);
the yarn model itself (stages/core/yarn/model.py: regular_xy for regular and loop pieces, hair_point for
hairs, mapped by Eq. 7 with curve_frame_at): exact at the vertices, and between them within the chord
error chord_error reports; continuity (pieces of one fibre share their end points); the documented order;
determinism whatever the thread count.
"""
import numba
import numpy as np
import pytest
from numba import njit

from pipeline.presets import load_preset, pack, scale_preset
from stages.core.curves.frames import curve_frame_at
from stages.core.curves.woven import woven_curves
from stages.core.yarn import model as M
from stages.ingest import weave
from stages.ingest.spline_process import curves_from_arrays, process_curves
from stages.procedural.realize import chord_error, realize_fill, realize_plan, yarn_counts, yarn_plan
from stages.procedural.tables import build_tables

RADIUS = 0.03
SPACING = 0.004   # realization step along the yarn


def _tp(name):
    d = scale_preset(load_preset(name), RADIUS)
    d["fiber_num"] = 12
    return pack(d)


@pytest.fixture(scope="module")
def fabric():
    warp, weft = woven_curves(weave.plain(2, 2), 0.3, 0.3, RADIUS, RADIUS, 0.5, 8)
    pts = np.concatenate([*warp, *weft])
    off = np.concatenate([[0], np.cumsum([len(p) for p in (*warp, *weft)])]).astype(np.int64)
    closed = np.zeros(4, bool)
    rad = np.full(4, RADIUS)
    cv = curves_from_arrays(pts, off, closed, rad, process_curves(pts, off, closed, rad))
    tparams = np.stack([_tp("cotton1"), _tp("polyester1")])
    ytype = np.array([0, 0, 1, 1], np.int32)
    albedo = np.array([[0.8, 0.7, 0.6]] * 2 + [[0.2, 0.3, 0.7]] * 2)
    tab, _ = build_tables(cv, tparams, ytype, albedo, 3)
    return cv, tab


def _realize(cv, tab):
    plan = realize_plan(tab, cv.curve_length, SPACING)
    yarn, ply, idx, kind, a0, a1, hz1, hze, nv = plan
    offsets = np.zeros(len(nv) + 1, np.int64)
    np.cumsum(nv, out=offsets[1:])
    pts = np.full((offsets[-1], 3), np.nan)
    rad = np.full(offsets[-1], np.nan)
    realize_fill(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, offsets, pts, rad)
    return plan, offsets, pts, rad


@pytest.fixture(scope="module")
def realized(fabric):
    return _realize(*fabric)


def test_counts_agree_with_the_plan_and_the_fill(fabric, realized):
    """Reference: per yarn and kind, yarn_counts' (vertices, pieces) == yarn_plan's; realize_plan is the
    yarns' plans in order; realize_fill writes every vertex (none left NaN) with its type's fibre radius;
    all three kinds occur."""
    cv, tab = fabric
    (yarn, ply, idx, kind, a0, a1, hz1, hze, nv), offsets, pts, rad = realized
    for c in range(len(tab.yarn_type)):
        L = float(cv.curve_length[c])
        v, p = yarn_counts(tab, c, L, SPACING)
        pl = yarn_plan(tab, c, L, SPACING)
        sel = yarn == c
        for k in (1, 2, 3):
            assert p[k] == np.sum(pl[2] == k) == np.sum(kind[sel] == k)
            assert v[k] == pl[7][pl[2] == k].sum() == nv[sel & (kind == k)].sum()
        for a, b in zip(pl, (ply, idx, kind, a0, a1, hz1, hze, nv)):
            np.testing.assert_array_equal(a, b[sel])
    assert set(np.unique(kind)) == {1, 2, 3}
    assert not np.isnan(pts).any() and not np.isnan(rad).any()
    rf = tab.tparams[tab.yarn_type[np.repeat(yarn, nv)], M.FIBER_RADIUS]
    np.testing.assert_array_equal(rad, rf)


def test_order_is_the_lookups_rank(realized):
    """Contract: fibres ordered by yarn, ply, regular and loop pieces (by fibre index, then along z) before
    hairs (by hair index)."""
    (yarn, ply, idx, kind, a0, a1, hz1, hze, nv), _, _, _ = realized
    key = np.stack([yarn, ply, (kind == 3).astype(int), idx, np.where(kind == 3, 0.0, a0)], axis=1)
    assert all(tuple(key[i]) < tuple(key[i + 1]) for i in range(len(key) - 1))


@njit
def _model_points(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, u):
    """The yarn model's fabric-space point of each piece at parameter fraction u[q] in [0, 1]: z = a0 + u (a1 -
    a0) through regular_xy (regular and loop pieces), t = u through hair_point (hairs), Eq. 7 via curve_frame_at."""
    out = np.empty((yarn.shape[0], 3))
    for q in range(yarn.shape[0]):
        c = yarn[q]
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        ys = np.uint64(tab.yarn_seed[c])
        if kind[q] == 3:
            r0, r1, th1, pe = M.hair_params(tp, ys, ply[q], idx[q])
            x, y, z = M.hair_point(tp, ply[q], r0, r1, th1, pe, hz1[q], hze[q], u[q])
        else:
            f = tab.type_fib_off[t] + ply[q] * int(tp[M.FIBER_NUM]) + idx[q]
            z = a0[q] + (a1[q] - a0[q]) * u[q]
            x, y, kd = M.regular_xy(tp, ys, ply[q], idx[q], tab.fib_R[f], tab.fib_th[f], tab.fib_th0[f], z)
        pos, tan, n, b = curve_frame_at(cv, c, z)
        for d in range(3):
            out[q, d] = pos[d] + x * n[d] + y * b[d]
    return out


def _point_segment_distance(p, a, b):
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - a - t[:, None] * ab, axis=1)


def test_fibres_lie_at_the_model_positions(fabric, realized):
    """Reference: the yarn model: every vertex is the model's point at its parameter (1e-12), and at the
    middle parameter of every segment the model's point lies within chord_error's sagitta bound of the
    segment (10 % margin: the bound estimates l theta / 8 from the turning angle at the vertices)."""
    cv, tab = fabric
    (yarn, ply, idx, kind, a0, a1, hz1, hze, nv), offsets, pts, _ = realized
    q = np.repeat(np.arange(len(nv)), nv)
    m = np.arange(len(q)) - offsets[q]
    u = m / (nv[q] - 1)
    ref = _model_points(cv, tab, yarn[q], ply[q], idx[q], kind[q], a0[q], a1[q], hz1[q], hze[q], u)
    np.testing.assert_allclose(pts, ref, rtol=0, atol=1e-12)
    seg = np.flatnonzero(m < nv[q] - 1)  # first vertex of every segment
    mid = _model_points(cv, tab, yarn[q[seg]], ply[q[seg]], idx[q[seg]], kind[q[seg]], a0[q[seg]], a1[q[seg]],
                        hz1[q[seg]], hze[q[seg]], (m[seg] + 0.5) / (nv[q[seg]] - 1))
    dev = _point_segment_distance(mid, pts[seg], pts[seg + 1])
    for k in (1, 2, 3):  # per kind: chord_error of that kind's polylines alone
        pieces = np.flatnonzero(kind == k)
        sub = np.concatenate([np.arange(offsets[i], offsets[i + 1]) for i in pieces])
        sag, turn = chord_error(pts[sub], np.concatenate([[0], np.cumsum(nv[pieces])]))
        dk = dev[kind[q[seg]] == k]
        assert 0.0 < sag and dk.max() <= 1.1 * sag, (k, dk.max(), sag)
        assert dk.max() > 0.25 * sag, (k, dk.max(), sag)  # not vacuous: the deviation reaches the bound's order


def test_pieces_of_a_fibre_share_end_points(realized):
    """Contract: a fibre's consecutive regular / loop pieces meet: a1 of one is a0 of the next and their
    end vertices coincide (R = rho_min R_j under both formulas there); the first starts at z = 0 and the
    last ends at the yarn's length."""
    (yarn, ply, idx, kind, a0, a1, hz1, hze, nv), offsets, pts, _ = realized
    fib = np.flatnonzero(kind != 3)
    n_joins = 0
    for i, j in zip(fib[:-1], fib[1:]):
        if (yarn[i], ply[i], idx[i]) == (yarn[j], ply[j], idx[j]):
            assert a1[i] == a0[j] and kind[i] != kind[j]
            np.testing.assert_allclose(pts[offsets[i + 1] - 1], pts[offsets[j]], atol=1e-12)
            n_joins += 1
        else:
            assert a0[j] == 0.0
    assert n_joins > 0


def test_realization_is_deterministic(fabric, realized):
    """Reference: the same bytes on one thread as on all (counter-based random numbers, prange over pieces)."""
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        plan, offsets, pts, rad = _realize(*fabric)
    finally:
        numba.set_num_threads(n0)
    assert pts.tobytes() == realized[2].tobytes() and rad.tobytes() == realized[3].tobytes()
    for a, b in zip(plan, realized[0]):
        assert a.tobytes() == b.tobytes()
