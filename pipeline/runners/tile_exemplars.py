"""The tile stage's exemplars: periodic fibre patches realized from weave drafts or knit patterns.

A tiling's exemplars are all woven or all knitted (``tiling_layout`` refuses a mix: the blocks of one
tiling share one cell size).

Woven: ``exemplar_interlacement`` turns one ``[[exemplars]]`` entry (plain, twill, satin, basket or a
WIF draft; ends x picks; invert) into its warp-over-weft interlacement, refusing a size that is not a
multiple of the draft's repeat; ``[weave]`` gives the spacing and the weave cells per block.

Knitted: an entry with pattern = stockinette | garter | rib1x1 and ``wales`` x ``courses`` stitches (default
the pattern's repeat: 1 x 1, garter 1 x 2, rib1x1 2 x 1; multiples of it) is realized by
``stages.tile.knit_exemplar`` from the ingest knit generator's loop model; ``[knit]`` gives spacing =
[wale spacing w, course spacing h] (default the generator's: [0.1, 0.8 w]) and block_stitches = [bx, by]
(stitches per block, default [1, 1]); the yarn radius defaults to the generator's (0.06 min(w, h / 0.8)).
A weft knit has no ends: its interlacement is stored as 0 ends x ``courses`` picks (each course a yarn of
group knit), so the exemplar size consumers read (ends + picks = yarns) holds.

``yarn_params`` packs the ``[yarn]`` table (a preset scaled to the yarn radius, with its overrides) and
the fibre polyline step. ``build_exemplars`` realizes every exemplar (``stages.tile.exemplar`` /
``stages.tile.knit_exemplar``), moves them into one exemplar space (every fibre surface in z in [0, T])
and cuts them into blocks.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..errors import LoomError

DEFAULT_SPACING = 0.1
DEFAULT_COURSE_RATIO = 0.8   # course spacing / wale spacing: the ingest knit generator's default
                             # (pipeline/generators.py)
WOVEN_KEYS = ("n", "m", "step", "invert", "path", "ends", "picks")
KNIT_KEYS = ("wales", "courses")


class YarnParams(NamedTuple):
    tparams: np.ndarray     # packed yarn parameters (stages.core.yarn.model)
    radius: float           # yarn radius
    segment_length: float   # fibre polyline step
    preset: dict            # the scaled preset with the [yarn] overrides


class Layout(NamedTuple):
    kind: str               # 'woven' or 'knit': every exemplar of a tiling is one kind
    spacing: tuple          # (sx, sy): warp and weft spacing, or wale and course spacing (w, h)
    block_cells: tuple      # (bx, by) weave cells or stitches per block
    sizes: list             # per exemplar (nx, ny) cells: (ends, picks) or (wales, courses)
    overs: list             # per exemplar: the interlacement (ends, picks), or the stitches (courses, wales)
    colors: list            # per exemplar: (color (Y, 3) float32 linear RGB, color_source (Y,) int8) of its yarns


class Exemplars(NamedTuple):
    exemplars: list         # one dict per exemplar (stages.tile.exemplar.realize_exemplar + over, name, blocks)
    thickness: float        # T: every fibre surface lies in z in [0, T]
    block_size: tuple       # (bw, bh) of one block in exemplar space


def _natural(ex):
    pat = ex["pattern"]
    n = ex.get("n")
    if pat == "plain":
        return 2, 2
    if pat == "twill":
        nn = n or 2
        return nn + (ex.get("m") or nn), nn + (ex.get("m") or nn)
    if pat == "satin":
        return n or 5, n or 5
    return 2 * (n or 2), 2 * (n or 2)


def exemplar_interlacement(ex, file, place):
    """(E, P) interlacement of one exemplar, checked to be periodic in the exemplar size."""
    from stages.ingest import weave

    pat = ex["pattern"]
    if pat == "wif":
        if "path" not in ex:
            raise LoomError(file, f"{place}.path", "pattern = 'wif' needs a path")
        from ..io.wif import parse

        over_big = parse(ex["path"]).over
        E, P = ex.get("ends", over_big.shape[0]), ex.get("picks", over_big.shape[1])
        big = over_big
    else:
        E0, P0 = _natural(ex)
        E, P = ex.get("ends", E0), ex.get("picks", P0)

        def gen(e, p):
            if pat == "plain":
                return weave.plain(e, p)
            if pat == "twill":
                n = ex.get("n", 2)
                return weave.twill(n, ex.get("m", n), e, p)
            if pat == "satin":
                return weave.satin(ex.get("n", 5), e, p, ex.get("step"))
            return weave.basket(ex.get("n", 2), e, p)
        try:
            big = gen(2 * E, 2 * P)
        except ValueError as e:
            raise LoomError(file, place, str(e)) from None
    from stages.tile.exemplar import check_periodic_draft

    if not check_periodic_draft(big, E, P):
        raise LoomError(file, place, f"the {pat} draft ({big.shape[0]} x {big.shape[1]} shown) is not periodic in the "
                                     f"exemplar size {E} ends x {P} picks: choose a multiple of the draft's repeat")
    over = big[:E, :P].copy()
    if ex.get("invert"):
        over = ~over
    return over


def exemplar_colors(ex, n_ends: int, n_picks: int):
    """(color (E+P, 3) float32, color_source (E+P,) int8) of an exemplar's yarns (ends, then picks, as
    ``stages.tile.exemplar`` numbers them): a WIF exemplar's thread colours (end e takes the draft's end
    e, modulo the draft's ends; likewise picks; ``invert`` keeps each thread's colour), source draft, else
    source yarn type (``pipeline.thread_colors``; the renderers give those the scene's group colour or the
    preset's albedo, ``pipeline.renderers.fiberpath.tiling_fibers``)."""
    from ..thread_colors import FROM_DRAFT, FROM_TYPE

    Y = n_ends + n_picks
    color = np.zeros((Y, 3), np.float32)
    source = np.full(Y, FROM_TYPE, np.int8)
    if ex.get("pattern") == "wif":
        from ..io.wif import parse

        d = parse(ex["path"])
        per_yarn = [d.warp_colors[e % len(d.warp_colors)] for e in range(n_ends)] + \
                   [d.weft_colors[p % len(d.weft_colors)] for p in range(n_picks)]
        for y, c in enumerate(per_yarn):
            if c is not None:
                color[y], source[y] = c, FROM_DRAFT
    return color, source


def is_knit(ex) -> bool:
    from stages.core.curves.knit import PATTERNS

    return ex.get("pattern") in PATTERNS


def fabric_kind(cfg, file) -> str:
    """'woven' or 'knit'; a mix of woven and knitted exemplars, or the other kind's table, is refused."""
    exs = cfg["exemplars"]
    kinds = ["knit" if is_knit(ex) else "woven" for ex in exs]
    kind = kinds[0]
    for k, (ex, kk) in enumerate(zip(exs, kinds)):
        if kk != kind:
            raise LoomError(file, f"exemplars[{k}].pattern", f"{ex['pattern']!r} is a {kk} pattern but exemplars[0] "
                            f"({exs[0]['pattern']!r}) is a {kind} pattern: a tiling's exemplars are all woven or all "
                            "knitted "
                            f"(its blocks share one cell size); make two tilings")
        wrong = WOVEN_KEYS if kk == "knit" else KNIT_KEYS
        for key in wrong:
            if key in ex:
                raise LoomError(file, f"exemplars[{k}].{key}", f"{key!r} does not apply to a {kk} exemplar "
                                f"({ex['pattern']!r}); " + ("a knitted exemplar takes wales and courses" if kk == "knit"
                                                            else "wales and courses are for knitted exemplars"))
    other = "weave" if kind == "knit" else "knit"
    if other in cfg:
        raise LoomError(file, other, f"a [{other}] table does not apply to {kind} exemplars; "
                        + ("a knitted tiling takes [knit] spacing = [w, h] and block_stitches" if kind == "knit"
                           else "a woven tiling takes [weave]"))
    return kind


def knit_spacing(cfg):
    """(w, h): wale and course spacing of a knitted tiling."""
    k = cfg.get("knit", {})
    if "spacing" in k:
        return float(k["spacing"][0]), float(k["spacing"][1])
    return DEFAULT_SPACING, DEFAULT_COURSE_RATIO * DEFAULT_SPACING


def knit_stitches(ex, file, place):
    """(wales, courses) of one knitted exemplar, checked to be whole repeats of its pattern."""
    from stages.tile.knit_exemplar import check_repeat, natural_repeat

    nw, nc = natural_repeat(ex["pattern"])
    wales, courses = int(ex.get("wales", nw)), int(ex.get("courses", nc))
    try:
        check_repeat(ex["pattern"], wales, courses)
    except ValueError as e:
        raise LoomError(file, f"{place}.{'courses' if courses % nc else 'wales'}", str(e)) from None
    return wales, courses


def tiling_layout(cfg, file) -> Layout:
    """The kind, cell spacing, cells per block, size and yarn colours of every exemplar, checked (before any
    fibre)."""
    kind = fabric_kind(cfg, file)
    places = [f"exemplars[{k}]" for k in range(len(cfg["exemplars"]))]
    if kind == "knit":
        from stages.core.curves.knit import stitch_types

        spacing = knit_spacing(cfg)
        cells = tuple(cfg.get("knit", {}).get("block_stitches", [1, 1]))
        sizes = [knit_stitches(ex, file, pl) for ex, pl in zip(cfg["exemplars"], places)]
        overs = [stitch_types(ex["pattern"], *sz) for ex, sz in zip(cfg["exemplars"], sizes)]
        colors = [exemplar_colors(ex, 0, courses) for ex, (_, courses) in zip(cfg["exemplars"], sizes)]
        names, what, key = ("wales", "courses"), "stitches", "knit.block_stitches"
    else:
        spacing = tuple(cfg.get("weave", {}).get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING]))
        cells = tuple(cfg.get("weave", {}).get("block_cells", [1, 1]))
        overs = [exemplar_interlacement(ex, file, pl) for ex, pl in zip(cfg["exemplars"], places)]
        sizes = [tuple(o.shape) for o in overs]
        colors = [exemplar_colors(ex, *o.shape) for ex, o in zip(cfg["exemplars"], overs)]
        names, what, key = ("ends", "picks"), "cells", "weave.block_cells"
    for pl, (nx, ny) in zip(places, sizes):
        if nx % cells[0] or ny % cells[1]:
            raise LoomError(file, pl, f"exemplar of {nx} {names[0]} x {ny} {names[1]} cannot be cut into blocks of "
                                      f"{cells[0]} x {cells[1]} {what} ({key})")
    return Layout(kind, (float(spacing[0]), float(spacing[1])), (int(cells[0]), int(cells[1])), sizes, overs, colors)


def default_radius(cfg, file) -> float:
    """The yarn radius without [yarn] radius: woven min(spacing) / 2.2, knitted the knit generator's."""
    if fabric_kind(cfg, file) == "knit":
        from stages.core.curves.knit import default_radius as knit_radius

        return knit_radius(*knit_spacing(cfg))
    sx, sy = cfg.get("weave", {}).get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING])
    return min(sx, sy) / 2.2


def exemplar_vertices(cfg, file, layout: Layout) -> float:
    """Fibre vertices of every exemplar (plies x fibres per yarn, a vertex per polyline step along its
    length), for the memory estimate; a knitted course's length is the loop model's (the arc length of its
    periodic centreline). The wrapped copies (counted in the tile runner's bytes per vertex) hold about as
    many again: 1.05 x for a 1 x 1 stockinette, whose loops reach 1.1 h beyond the box, as measured."""
    from stages.core.yarn import model as M

    tp, radius, seg, _ = yarn_params(cfg, file)
    fibres = tp[M.PLY_NUM] * tp[M.FIBER_NUM]
    sx, sy = layout.spacing
    if layout.kind == "woven":
        return float(sum(fibres * (E * (P * sy * 1.5 / seg + 2) + P * (E * sx * 1.5 / seg + 2))
                         for E, P in layout.sizes))
    from stages.tile.knit_exemplar import knit_centreline

    verts = 0.0
    for ex, (wales, courses) in zip(cfg["exemplars"], layout.sizes):
        L = knit_centreline(ex["pattern"], wales, courses, sx, sy, radius, 0).L
        verts += fibres * courses * (L / seg + 2)
    return float(verts)


def yarn_params(cfg, file) -> YarnParams:
    from stages.core.yarn import model as M

    from ..presets import load_preset, pack, packed_fibre_radius, scale_preset

    y = cfg.get("yarn", {})
    radius = y["radius"] if "radius" in y else default_radius(cfg, file)
    d = load_preset(y.get("preset", "cotton1"), file, "yarn.preset")
    d = scale_preset(d, float(radius), file, "yarn.radius")
    if "fibers_per_ply" in y:  # the packed fibre radius follows the count (unless fiber_radius is given)
        d["fiber_num"] = int(y["fibers_per_ply"])
        d["fiber_radius"] = packed_fibre_radius(d)
    if "fiber_radius" in y:
        d["fiber_radius"] = float(y["fiber_radius"])
    if "use_migration" in y:
        d["use_migration"] = int(y["use_migration"])
    d["use_flyaways"] = 0
    tp = pack(d)
    seg = y.get("segment_length", min(tp[M.ALPHA], tp[M.YARN_ALPHA], 2 * math.pi * radius) / 12.0)
    return YarnParams(tp, float(radius), float(seg), d)


def build_exemplars(cfg, file, layout: Layout | None = None) -> Exemplars:
    from stages.tile.exemplar import realize_exemplar, segment_blocks, wrap_pieces
    from stages.tile.knit_exemplar import realize_knit_exemplar

    layout = layout or tiling_layout(cfg, file)
    tp, radius, seg_len, _ = yarn_params(cfg, file)
    sx, sy = layout.spacing
    bcx, bcy = layout.block_cells
    crimp = cfg.get("weave", {}).get("crimp", 1.0)
    seed = int(cfg.get("seed", 0))
    exs = []
    for k, (ex, over, (nx, ny)) in enumerate(zip(cfg["exemplars"], layout.overs, layout.sizes)):
        if layout.kind == "knit":
            try:
                r = realize_knit_exemplar(ex["pattern"], nx, ny, sx, sy, tp, radius, seed, seg_len)
            except ValueError as e:
                raise LoomError(file, f"exemplars[{k}]", str(e)) from None
            r["over"] = np.zeros((0, ny), bool)   # a weft knit: 0 ends x courses picks (module doc)
        else:
            r = realize_exemplar(over, sx, sy, tp, tp, radius, radius, crimp, seed, seg_len)
            r["over"] = over
        r["name"] = ex.get("name", f"{ex['pattern']}{k}")
        r["nblocks"] = (nx // bcx, ny // bcy)
        exs.append(r)
    # common exemplar space: z shifted so that every fibre surface lies in [0, T]
    zlo = min(float((e["points"][:, 2] - e["radius"]).min()) for e in exs)
    zhi = max(float((e["points"][:, 2] + e["radius"]).max()) for e in exs)
    pad = 1e-3 * (zhi - zlo)
    for e in exs:
        e["points"] = e["points"] - np.array([0.0, 0.0, zlo - pad])
    T = (zhi - zlo) + 2 * pad
    bw, bh = bcx * sx, bcy * sy
    for e in exs:
        e["wrap"] = wrap_pieces(e)
        e["seg_block"] = segment_blocks(e, bw, bh)
    return Exemplars(exs, T, (bw, bh))
