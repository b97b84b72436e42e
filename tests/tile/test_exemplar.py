"""Exemplars (stages/tile/exemplar.py), called directly on a 2 x 2 plain weave (cotton1 scaled to the
spacing, 6 fibres per ply).

References: periodicity (a warp end continues itself after (0, H), a weft pick after (W, 0), centreline,
frame and fibres alike); the snapped pitches are whole fractions of the repeat; brute force over every
segment of every periodic copy for ``wrap_pieces`` (which capsules reach the exemplar box) and for
``segment_blocks`` (which block holds a segment's midpoint); hand-made drafts for ``check_periodic_draft``.
"""
import math

import numpy as np
import pytest

from pipeline.presets import load_preset, pack, scale_preset
from stages.core.yarn import model as M
from stages.ingest import weave
from stages.tile.exemplar import (
    centreline_frames,
    check_periodic_draft,
    periodic_centreline,
    realize_exemplar,
    segment_blocks,
    snap_periodic,
    wrap_pieces,
)

SX, SY, R = 0.1, 0.12, 0.045


def _tp():
    d = scale_preset(load_preset("cotton1"), R)
    d["fiber_num"] = 6
    d["use_flyaways"] = 0
    return pack(d)


@pytest.fixture(scope="module")
def ex():
    tp = _tp()
    seg = min(tp[M.ALPHA], tp[M.YARN_ALPHA], 2 * math.pi * R) / 12.0
    return realize_exemplar(weave.plain(2, 2), SX, SY, tp, tp, R, R, 1.0, 5, seg)


def test_centreline_and_frames_are_periodic():
    """Reference: c(s + L) = c(s) + (0, H, 0) for a warp end, + (W, 0, 0) for a weft pick, with the same
    tangent, normal and binormal, at 50 arc lengths s in [-L/2, L/2] of every yarn of the repeat (the
    sampled centreline covers the neighbouring repeats up to half a cell before their last crossing)."""
    over = weave.plain(2, 2)
    W, H = 2 * SX, 2 * SY
    for warp, idx in ((True, 0), (True, 1), (False, 0), (False, 1)):
        s, pts, L = periodic_centreline(over, SX, SY, R, R, 1.0, warp, idx)
        z = np.linspace(-0.5 * L, 0.5 * L, 50)
        a = centreline_frames(s, pts, z)
        b = centreline_frames(s, pts, z + L)
        shift = np.array([0.0, H, 0.0]) if warp else np.array([W, 0.0, 0.0])
        np.testing.assert_allclose(b[0], a[0] + shift, atol=1e-12)
        for k in (1, 2, 3):
            np.testing.assert_allclose(b[k], a[k], atol=1e-9)
        # the start of the repeat is the exemplar's lower edge
        assert centreline_frames(s, pts, np.zeros(1))[0][0, 1 if warp else 0] == pytest.approx(0.0, abs=1e-12)


def test_snapped_pitches_divide_the_repeat():
    """Reference: L / alpha and L / yarn_alpha are whole numbers, s_mig times the fibre turns too; flyaways
    off; the input untouched."""
    tp = _tp()
    before = tp.copy()
    L = 0.2371
    q = snap_periodic(tp, L)
    np.testing.assert_array_equal(tp, before)
    n_f = L / q[M.ALPHA]
    for v in (n_f, L / q[M.YARN_ALPHA], q[M.S_MIG] * n_f):
        assert v == pytest.approx(round(v), abs=1e-9) and round(v) >= 1
    assert q[M.USE_FLYAWAYS] == 0.0


def test_fibres_re_enter_at_the_opposite_side(ex):
    """Reference: periodicity: every fibre's last point is its first point moved by one period ((0, H) for
    warp ends, (W, 0) for weft picks) -- it leaves the exemplar on one side and re-enters on the other --
    and the fibres of the 3 x 3 copies meet without a seam (the set of end points is the set of start
    points moved by a period)."""
    W, H = ex["period"]
    assert (W, H) == pytest.approx((2 * SX, 2 * SY))
    P, O = ex["points"], ex["offsets"]
    assert len(O) - 1 == 4 * 3 * 6  # 4 yarns x 3 plies x 6 fibres
    first, last = P[O[:-1]], P[O[1:] - 1]
    warp = ex["yarn_group"][ex["fiber_yarn"]] == 0
    shift = np.where(warp[:, None], [0.0, H, 0.0], [W, 0.0, 0.0])
    np.testing.assert_allclose(last, first + shift, atol=1e-9)
    # the fibres really move: not a degenerate polyline
    assert np.all(np.linalg.norm(np.diff(P, axis=0), axis=1)[np.setdiff1d(np.arange(len(P) - 1), O[1:-1] - 1)] > 0)


def _segments(ex):
    """(a, b, r, global segment id) of every exemplar segment (fibre f's first segment is offsets[f] - f)."""
    P, Rr, O = ex["points"], ex["radius"], ex["offsets"]
    idx = np.concatenate([np.arange(O[f], O[f + 1] - 1) for f in range(len(O) - 1)])
    fib = np.concatenate([np.full(O[f + 1] - O[f] - 1, f) for f in range(len(O) - 1)])
    return P[idx], P[idx + 1], np.maximum(Rr[idx], Rr[idx + 1]), idx - fib


def _seg_box_d2(a, b, lo, hi, n=64):
    """Squared distance of segments to a box, by dense sampling of the segment (an upper bound, tight to
    (|b - a| / n)^2)."""
    t = np.linspace(0.0, 1.0, n)
    p = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    d = np.maximum(0.0, np.maximum(lo - p, p - hi))
    return (d * d).sum(axis=2).min(axis=1)


def test_wrap_pieces_cover_every_capsule_touching_the_box(ex):
    """Reference: brute force over every segment of the 3 x 3 copies: wrap_pieces keeps exactly those whose
    capsule box meets [0, W] x [0, H], once each, with the right exemplar segment id and shift; and every
    capsule of the 5 x 5 copies that truly reaches the exemplar box (distance < its radius) is among them."""
    W, H = ex["period"]
    a, b, r, sid = _segments(ex)
    want = set()
    for sa in (-1, 0, 1):
        for sb in (-1, 0, 1):
            sh = np.array([sa * W, sb * H, 0.0])
            lo = np.minimum(a, b) + sh - r[:, None]
            hi = np.maximum(a, b) + sh + r[:, None]
            keep = (hi[:, 0] >= 0) & (lo[:, 0] <= W) & (hi[:, 1] >= 0) & (lo[:, 1] <= H)
            want |= {(int(s), sa, sb) for s in sid[keep]}
    wp = wrap_pieces(ex)
    got = []
    first_point = {int(s): i for s, i in zip(sid, np.concatenate([np.arange(ex["offsets"][f], ex["offsets"][f + 1] - 1)
                                                                   for f in range(len(ex["offsets"]) - 1)]))}
    for p in range(len(wp["offsets"]) - 1):
        lo_, hi_ = wp["offsets"][p], wp["offsets"][p + 1]
        for m in range(hi_ - lo_ - 1):
            s = int(wp["piece_seg0"][p]) + m
            d = wp["points"][lo_ + m] - ex["points"][first_point[s]]
            sa, sb = round(d[0] / W), round(d[1] / H)
            np.testing.assert_allclose(d, [sa * W, sb * H, 0.0], atol=1e-12)
            np.testing.assert_allclose(wp["points"][lo_ + m + 1], ex["points"][first_point[s] + 1] + d, atol=1e-12)
            got.append((s, sa, sb))
    assert len(got) == len(set(got))
    assert set(got) == want
    # the contract the pieces exist for: every capsule reaching the box, from any nearby copy
    box_lo, box_hi = np.zeros(3), np.array([W, H, np.inf])
    box_lo[2] = -np.inf
    for sa in range(-2, 3):
        for sb in range(-2, 3):
            sh = np.array([sa * W, sb * H, 0.0])
            reach = _seg_box_d2(a + sh, b + sh, box_lo, box_hi) < r * r
            assert {(int(s), sa, sb) for s in sid[reach]} <= set(got)


@pytest.mark.parametrize("bcx, bcy", [(1, 1), (2, 1), (1, 2)])
def test_segment_blocks_by_brute_force(ex, bcx, bcy):
    """Reference: for every segment, the block (search over all blocks of the exemplar) whose cell
    [bx bw, (bx + 1) bw) x [by bh, (by + 1) bh) holds its midpoint moved into the exemplar by whole
    periods; id = bx + nbx by; exactly one block each."""
    W, H = ex["period"]
    bw, bh = bcx * SX, bcy * SY
    nbx, nby = 2 // bcx, 2 // bcy
    a, b, _, sid = _segments(ex)
    ids = segment_blocks(ex, bw, bh)
    assert len(ids) == len(sid)
    m = 0.5 * (a + b)
    for k in range(0, len(m), 7):
        x, y = m[k, 0], m[k, 1]
        x -= W * math.floor(x / W)
        y -= H * math.floor(y / H)
        hits = [bx + nbx * by for bx in range(nbx) for by in range(nby)
                if bx * bw <= x < (bx + 1) * bw and by * bh <= y < (by + 1) * bh]
        assert hits == [ids[sid[k]]]


def test_check_periodic_draft():
    """Reference: hand-made drafts: a 2 x 2 plain weave tiled 3 x 2 repeats every 2 x 2 (and every 4 x 2),
    not every 3 x 2; one changed crossing breaks it."""
    big = np.tile(weave.plain(2, 2), (3, 2))
    assert check_periodic_draft(big, 2, 2)
    assert not check_periodic_draft(big, 4, 2)  # 6 ends are not a multiple of 4
    assert not check_periodic_draft(big, 3, 2)
    big[5, 3] = ~big[5, 3]
    assert not check_periodic_draft(big, 2, 2)
    assert check_periodic_draft(np.tile(weave.twill(2, 1, 3, 3), (2, 2)), 3, 3)
