"""The tile stage's exemplars: periodic fibre patches realized from weave drafts.

``exemplar_interlacement`` turns one ``[[exemplars]]`` entry (plain, twill, satin, basket or a WIF
draft; ends x picks; invert) into its warp-over-weft interlacement, refusing a size that is not a
multiple of the draft's repeat. ``yarn_params`` packs the ``[yarn]`` table (a preset scaled to the
yarn radius, with its overrides) and the fibre polyline step. ``build_exemplars`` realizes every
exemplar (``stages.tile.exemplar``), moves them into one exemplar space (every fibre surface in
z in [0, T]) and cuts them into blocks of ``weave.block_cells``.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..errors import LoomError

DEFAULT_SPACING = 0.1


class YarnParams(NamedTuple):
    tparams: np.ndarray     # packed yarn parameters (stages.core.yarn.model)
    radius: float           # yarn radius
    segment_length: float   # fibre polyline step
    preset: dict            # the scaled preset with the [yarn] overrides


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


def yarn_params(cfg, file) -> YarnParams:
    from stages.core.yarn import model as M

    from ..presets import load_preset, pack, packed_fibre_radius, scale_preset

    y = cfg.get("yarn", {})
    sx, sy = cfg.get("weave", {}).get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING])
    radius = y.get("radius", min(sx, sy) / 2.2)
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


def build_exemplars(cfg, file) -> Exemplars:
    from stages.tile.exemplar import realize_exemplar, segment_blocks, wrap_pieces

    tp, radius, seg_len, _ = yarn_params(cfg, file)
    wv = cfg.get("weave", {})
    sx, sy = wv.get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING])
    crimp = wv.get("crimp", 1.0)
    bcx, bcy = wv.get("block_cells", [1, 1])
    seed = int(cfg.get("seed", 0))
    exs = []
    for k, ex in enumerate(cfg["exemplars"]):
        place = f"exemplars[{k}]"
        over = exemplar_interlacement(ex, file, place)
        E, P = over.shape
        if E % bcx or P % bcy:
            raise LoomError(file, f"{place}", f"exemplar of {E} ends x {P} picks cannot be cut into blocks of "
                                               f"{bcx} x {bcy} cells (weave.block_cells)")
        r = realize_exemplar(over, sx, sy, tp, tp, radius, radius, crimp, seed, seg_len)
        r["over"] = over
        r["name"] = ex.get("name", f"{ex['pattern']}{k}")
        r["nblocks"] = (E // bcx, P // bcy)
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
