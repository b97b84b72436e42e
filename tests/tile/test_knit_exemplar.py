"""Knitted exemplars (stages/tile/knit_exemplar.py) and knitted tilings (pipeline/runners/tile_exemplars.py).

References: the ingest knit generator's loop model (the centreline is its curve: the same function, the
same samples where a larger generated fabric and the exemplar overlap, shifted by whole stitches and
courses); periodicity (c(s + L) = c(s) + (W, 0, 0) for centreline and frame, every fibre's last point its
first point moved by one period); brute force over every segment of the 5 x 5 periodic copies for
``wrap_pieces`` (every capsule that reaches the exemplar box is kept, from the 3 x 3 copies); the moved
loop model is the ingest generator's very objects (so ingest is unchanged byte for byte; its own tests
in tests/ingest/test_generators.py run unchanged); the tile CLI's contract for bad input (exit 2, one
line naming the file and the place).
"""
import math

import numpy as np
import pytest

from pipeline.presets import load_preset, pack, scale_preset
from stages.core.curves import knit as core_knit
from stages.core.yarn import model as M
from stages.tile.exemplar import centreline_frames, wrap_pieces
from stages.tile.knit_exemplar import DENSE_STITCH, KNIT_GROUP, knit_centreline, natural_repeat, realize_knit_exemplar

W_SP, H_SP = 0.25, 0.2
R = core_knit.default_radius(W_SP, H_SP)
CASES = [("stockinette", 1, 1), ("garter", 1, 2), ("rib1x1", 2, 1), ("stockinette", 2, 3)]


def _tp(fibers=3):
    d = scale_preset(load_preset("cotton1"), R)
    d["fiber_num"] = fibers
    d["use_flyaways"] = 0
    return pack(d)


def _realize(pattern, wales, courses, seg=None):
    tp = _tp()
    seg = seg or min(tp[M.ALPHA], tp[M.YARN_ALPHA], 2 * math.pi * R) / 12.0
    return realize_knit_exemplar(pattern, wales, courses, W_SP, H_SP, tp, R, 7, seg)


def test_ingest_generator_is_the_core_loop_model():
    """Reference: the ingest stage's knit generator names are the objects of stages.core.curves.knit (the
    code moved, not copied), so ingest's curves are the core's byte for byte."""
    from stages.ingest import knit as ingest_knit

    for name in ("knit_curves", "stitch_types", "default_radius", "PATTERNS", "LOOP_HALF_HEIGHT", "DEPTH_FACTOR"):
        assert getattr(ingest_knit, name) is getattr(core_knit, name), name


@pytest.mark.parametrize("pattern,wales,courses", CASES)
def test_centreline_is_the_generators_curve(pattern, wales, courses):
    """Reference: knit_curves of a larger fabric (the generator's 16 samples per stitch, 3 repeats + 2
    stitches x 3 repeats + 2 courses): in its interior, course k over stitches j0..j0 + wales equals the
    exemplar's course k mod courses over its repeat, moved by whole stitches and courses."""
    NW, NC = 3 * wales + 2, 3 * courses + 2
    g, _ = core_knit.knit_curves(pattern, NW, NC, W_SP, H_SP, R, 16)
    step = DENSE_STITCH // 16
    for k in range(courses, 2 * courses):
        e = knit_centreline(pattern, wales, courses, W_SP, H_SP, R, k % courses).points
        for j0 in (wales, 2 * wales):
            m = np.arange(16 * wales + 1)
            got = e[(wales * 16 + m) * step]
            want = g[k, 16 * j0 + m] - np.array([W_SP * j0 - 0.5 * W_SP * NW,
                                                  H_SP * (k - k % courses) - 0.5 * H_SP * NC, 0.0])
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("pattern,wales,courses", CASES)
def test_centreline_and_frame_are_periodic(pattern, wales, courses):
    """Reference: c(s + L) = c(s) + (W, 0, 0) with the same tangent, normal and binormal at 60 arc lengths
    s in [-L/2, L/2]; the repeat starts at the sinker x = 0; the frame's n is the +z component normal to
    the tangent (n.t = 0, n.z > 0), and the tangent keeps a horizontal part (never parallel to z)."""
    W = wales * W_SP
    for i in range(courses):
        c = knit_centreline(pattern, wales, courses, W_SP, H_SP, R, i)
        z = np.linspace(-0.5 * c.L, 0.5 * c.L, 60)
        a = centreline_frames(c.s, c.points, z)
        b = centreline_frames(c.s, c.points, z + c.L)
        np.testing.assert_allclose(b[0], a[0] + [W, 0.0, 0.0], rtol=0, atol=1e-12)
        for q in (1, 2, 3):
            np.testing.assert_allclose(b[q], a[q], rtol=0, atol=1e-9)
        assert centreline_frames(c.s, c.points, np.zeros(1))[0][0, 0] == pytest.approx(0.0, abs=1e-12)
        _, t, n, _ = centreline_frames(c.s, c.points, np.linspace(0.0, c.L, 2000))
        np.testing.assert_allclose(np.einsum("ij,ij->i", t, n), 0.0, atol=1e-12)
        assert n[:, 2].min() > 0.5
        assert np.linalg.norm(t[:, :2], axis=1).min() > 0.6   # 0.66 (garter) .. 0.76 (stockinette) measured


@pytest.mark.parametrize("pattern,wales,courses", CASES)
def test_fibres_close_after_one_period(pattern, wales, courses):
    """Reference: periodicity: every fibre's last point is its first point moved by (W, 0, 0) -- it leaves
    the exemplar at x = W and re-enters at x = 0 -- the fibres are not degenerate, and each course is one
    yarn of group knit."""
    ex = _realize(pattern, wales, courses)
    W, H = ex["period"]
    assert (W, H) == pytest.approx((wales * W_SP, courses * H_SP))
    P, O = ex["points"], ex["offsets"]
    assert len(O) - 1 == courses * 3 * 3                    # courses x 3 plies x 3 fibres
    np.testing.assert_allclose(P[O[1:] - 1], P[O[:-1]] + [W, 0.0, 0.0], rtol=0, atol=1e-9)
    steps = np.linalg.norm(np.diff(P, axis=0), axis=1)
    inner = np.setdiff1d(np.arange(len(P) - 1), O[1:-1] - 1)  # steps within a fibre
    assert steps[inner].min() > 0
    assert np.array_equal(ex["yarn_group"], np.full(courses, KNIT_GROUP))
    assert np.array_equal(np.unique(ex["fiber_yarn"]), np.arange(courses))
    # the loop depth: a knit is thicker than a woven cloth (centreline z in [-3 r, 3 r], garter 5 r)
    depth = 5.0 if pattern == "garter" else 3.0
    assert P[:, 2].max() - P[:, 2].min() > 2 * depth * R


def _segment_table(ex):
    """(a, b, r, global segment id) of every exemplar segment (fibre f's first segment is offsets[f] - f)."""
    P, Rr, O = ex["points"], ex["radius"], ex["offsets"]
    idx = np.concatenate([np.arange(O[f], O[f + 1] - 1) for f in range(len(O) - 1)])
    fib = np.concatenate([np.full(O[f + 1] - O[f] - 1, f) for f in range(len(O) - 1)])
    return P[idx], P[idx + 1], np.maximum(Rr[idx], Rr[idx + 1]), idx - fib, idx


@pytest.mark.parametrize("pattern,wales,courses", [("stockinette", 1, 1), ("garter", 1, 2), ("rib1x1", 2, 1)])
def test_wrap_pieces_hold_every_capsule_reaching_the_box(pattern, wales, courses):
    """Reference: brute force over every segment of the 5 x 5 periodic copies: every capsule whose distance
    to the box [0, W] x [0, H] (x, y; z free) is below its radius, measured on 33 points along the
    segment, is among the wrapped pieces with its exemplar segment id and its shift; none comes from a
    copy two periods away (the loops reach 1.1 h into the courses above and below, the 3 x 3 copies still
    suffice); and wrap_pieces keeps exactly the 3 x 3 copies' segments whose capsule box meets the box."""
    ex = _realize(pattern, wales, courses, seg=0.02)
    W, H = ex["period"]
    a, b, r, sid, pidx = _segment_table(ex)
    wp = wrap_pieces(ex)
    got = set()
    point_of = dict(zip(sid.tolist(), pidx.tolist()))
    for p in range(len(wp["offsets"]) - 1):
        lo, hi = int(wp["offsets"][p]), int(wp["offsets"][p + 1])
        s0 = int(wp["piece_seg0"][p])
        shift = wp["points"][lo] - ex["points"][point_of[s0]]
        sa, sb = (int(round(shift[0] / W)), int(round(shift[1] / H)))
        np.testing.assert_allclose(shift, [sa * W, sb * H, 0.0], atol=1e-12)
        for q in range(hi - lo - 1):
            got.add((s0 + q, sa, sb))
    t = np.linspace(0.0, 1.0, 33)
    reach, boxed = set(), set()
    for sa in range(-2, 3):
        for sb in range(-2, 3):
            sh = np.array([sa * W, sb * H])
            pts = a[:, None, :2] + t[None, :, None] * (b - a)[:, None, :2] + sh
            d = np.maximum(0.0, np.maximum(-pts, pts - [W, H]))
            near = np.sqrt((d * d).sum(axis=2)).min(axis=1) < r
            reach |= {(int(s), sa, sb) for s in sid[near]}
            lo = np.minimum(a, b)[:, :2] + sh - r[:, None]
            hi = np.maximum(a, b)[:, :2] + sh + r[:, None]
            meets = (hi[:, 0] >= 0) & (lo[:, 0] <= W) & (hi[:, 1] >= 0) & (lo[:, 1] <= H)
            if abs(sa) <= 1 and abs(sb) <= 1:
                boxed |= {(int(s), sa, sb) for s in sid[meets]}
            else:
                assert not meets.any(), (sa, sb)
    assert reach and reach <= got
    assert got == boxed
    # the loops do reach across the box's lower and upper edges: copies shifted in y are needed
    assert any(sb != 0 for _, _, sb in reach)


def test_natural_repeats_and_refusals():
    """Reference: the patterns' repeats (stockinette 1 x 1, garter 1 wale x 2 courses, rib1x1 2 wales x 1
    course); a size that is not a whole number of repeats, or an unknown pattern, raises ValueError."""
    assert [natural_repeat(p) for p in core_knit.PATTERNS] == [(1, 1), (1, 2), (2, 1)]
    for args in (("garter", 1, 3), ("rib1x1", 3, 1), ("stockinette", 0, 1)):
        with pytest.raises(ValueError):
            _realize(*args)
    with pytest.raises(ValueError, match="knit pattern"):
        natural_repeat("seed")
    with pytest.raises(ValueError, match="3 x 3 wrapped copies"):  # loops reaching more than a period beyond
        tp = _tp()
        realize_knit_exemplar("stockinette", 1, 1, W_SP, 0.02, tp, R, 7, 0.05)


# ------------------------------------------------------------------------------------------------ tile CLI
KNIT_CFG = """
seed = 3
[yarn]
fibers_per_ply = 2
segment_length = 0.03
{knit}
[[exemplars]]
name = "knit"
pattern = "{pattern}"
{ex_extra}
{more}
[tiling]
repeat = [2, 2]
[surface]
kind = "flat"
resolution = [2, 2]
"""


def _cfg(tmp_path, name, pattern="stockinette", ex_extra="", knit='[knit]\nspacing = [0.25, 0.2]', more=""):
    p = tmp_path / f"{name}.toml"
    p.write_text(KNIT_CFG.format(pattern=pattern, ex_extra=ex_extra, knit=knit, more=more))
    return p


def test_knitted_tiling_for_the_consumers(tmp_path, cli):
    """Reference: the tiling artifact's contract as its consumers read it (fiberpath's ``tiling_fibers``,
    the shell scene, the inspector's exemplar sizes): a garter exemplar of 1 wale x 2 courses is 0 ends x 2
    picks (two yarns of group knit), its period is (w, 2 h), its blocks 1 x 2 stitches, every fibre surface
    lies in the shell's thickness (z in [0, T]), which is at least the knit's 2 x (5 r + fibre) loop depth."""
    from pipeline.artifacts import Artifact
    from pipeline.renderers.fiberpath import tiling_fibers
    from pipeline.runners.tile import load_tiling
    from pipeline.scene import load_scene
    from tests.helpers import ROOT

    cfg = _cfg(tmp_path, "garter", pattern="garter", ex_extra="courses = 2")
    out = tmp_path / "knit.zarr"
    code, _, err = cli("tile", cfg, "-o", out)
    assert code == 0, err
    art = Artifact(out)
    s = art.summary
    assert s["exemplar_sizes"] == [[0, 2]] and s["exemplar_kind"] == "knit" and s["exemplar_stitches"] == [[1, 2]]
    assert np.array_equal(art["ex_yarn_group"], [KNIT_GROUP, KNIT_GROUP]) and len(art["ex_over"]) == 0
    np.testing.assert_allclose(art["ex_period"], [[0.25, 0.4]])
    np.testing.assert_array_equal(art["ex_nblocks"], [[1, 2]])
    np.testing.assert_allclose(art["block_size"], [0.25, 0.2])
    assert s["block_grid"] == [2, 4]
    z = art["ex_points"][:, 2]
    rad = art["ex_radius"]
    assert (z - rad).min() >= 0.0 and (z + rad).max() <= s["thickness"]
    assert s["thickness"] >= 10 * R
    fib = tiling_fibers(load_scene(ROOT / "data" / "scenes" / "knit_swatch.toml"), art)
    np.testing.assert_allclose(fib.yarn_albedo, [[0.80, 0.22, 0.15]] * 2)
    sc, _ = load_tiling(out)
    assert sc is not None


BAD = {
    "mixed": (dict(more='[[exemplars]]\npattern = "plain"'), "exemplars[1].pattern", "all woven or all knitted"),
    "garter_odd": (dict(pattern="garter", ex_extra="courses = 3"), "exemplars[0].courses", "repeats every"),
    "rib_odd": (dict(pattern="rib1x1", ex_extra="wales = 3"), "exemplars[0].wales", "repeats every"),
    "woven_key": (dict(ex_extra="ends = 2"), "exemplars[0].ends", "wales and courses"),
    "weave_table": (dict(knit='[weave]\nspacing = [0.1, 0.1]'), "weave", "does not apply"),
    "spacing": (dict(knit='[knit]\nspacing = [0.25, -0.2]'), "knit.spacing", ""),
    "typo": (dict(pattern="stockinete"), "exemplars[0].pattern", "stockinette"),
    "blocks": (dict(knit='[knit]\nblock_stitches = [1, 2]'), "exemplars[0]", "knit.block_stitches"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_knit_config_exit_2(case, tmp_path, cli):
    """Reference: the CLI contract (docs/architecture.md): exit code 2, one line naming the file and the
    place, no artifact written."""
    kw, place, words = BAD[case]
    cfg = _cfg(tmp_path, case, **kw)
    out = tmp_path / "out.zarr"
    code, stdout, err = cli("tile", cfg, "-o", out)
    assert code == 2, (stdout, err)
    line = err.strip()
    assert "\n" not in line and f"{case}.toml" in line and place in line and words in line, line
    assert not out.exists()
