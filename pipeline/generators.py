"""Generated fabrics -> CurveSet: the scene table ``[fabric.generator]`` and WIF drafts.

``generate(gen, yarn_radius)`` reads the generator table (schemas/scene.schema.json
``$defs/generator``):

- kind = "woven": pattern plain | twill (n/m, default 2/2) | satin (n, default 5) | basket (n,
  default 2); ``ends`` x ``picks`` threads (default 16 x 16) ``spacing`` apart (default 0.1 scene
  units), ``crimp`` in yarn radii (default 1), ``samples_per_cell`` (default 6). One curve per
  warp end (group warp) and per weft pick (group weft), see stages/ingest/woven.py.
- kind = "knit": pattern stockinette | garter | rib1x1; ``ends`` wales x ``picks`` courses,
  wale ``spacing`` (default 0.1), ``course_spacing`` (default 0.8 x spacing),
  ``samples_per_cell`` control points per stitch (default 16). One open curve per course
  (group knit), see stages/ingest/knit.py.

Either kind folds into ``pleats = { count, depth }`` across x when the table says so (``pleated``).

The yarn radius is ``gen["yarn_radius"]``, else the ``yarn_radius`` argument (the scene's yarn
type), else a spacing-based default (woven: spacing / 4; knit: see knit.py). Every curve
carries that radius as its per-point radius.

``from_wif(path, scale, crimp, max_threads, repeat)`` parses a WIF draft (pipeline/io/wif.py),
tiles it ``repeat = [along ends, along picks]`` times, keeps at most ``max_threads`` ends and
picks, and weaves it like the woven generator with the draft's spacing, thickness and colours.
Invalid parameters raise LoomError naming ``fabric.generator`` (or the WIF file).
"""
from __future__ import annotations

import numpy as np

from .curveset import CurveSet
from .errors import LoomError

WOVEN = ("plain", "twill", "satin", "basket")
KNIT = ("stockinette", "garter", "rib1x1")


def woven_curveset(over, spacing_x, spacing_y, radius_warp, radius_weft, crimp=1.0, samples_per_cell=6,
                   warp_colors=None, weft_colors=None, source="woven", notes=None) -> CurveSet:
    from stages.core.curves.woven import woven_curves

    warp, weft = woven_curves(over, spacing_x, spacing_y, radius_warp, radius_weft, crimp, samples_per_cell)
    E, P = over.shape
    points = [warp[e] for e in range(E)] + [weft[p] for p in range(P)]
    radii = ([np.full(warp.shape[1], radius_warp) for _ in range(E)]
             + [np.full(weft.shape[1], radius_weft) for _ in range(P)])
    colors = list(warp_colors or [None] * E) + list(weft_colors or [None] * P)
    n = dict(notes or {})
    n.update(interlacement=np.asarray(over, dtype=bool), spacing=(float(spacing_x), float(spacing_y)),
             yarn_radius=(float(radius_warp), float(radius_weft)), crimp=float(crimp),
             samples_per_cell=int(samples_per_cell))
    return CurveSet(points=points, closed=[False] * (E + P), group=["warp"] * E + ["weft"] * P,
                    point_radius=radii, color=colors, curve_type="catmull-rom", source_format=source, notes=n)


def _interlacement(pattern, gen, ends, picks):
    from stages.ingest import weave

    if pattern == "plain":
        return weave.plain(ends, picks)
    if pattern == "twill":
        return weave.twill(int(gen.get("n", 2)), int(gen.get("m", gen.get("n", 2))), ends, picks)
    if pattern == "satin":
        return weave.satin(int(gen.get("n", 5)), ends, picks, gen.get("step"))
    return weave.basket(int(gen.get("n", 2)), ends, picks)


def pleated(cs: CurveSet, pleats: dict | None) -> CurveSet:
    """The curves folded into ``pleats['count']`` pleats across x, ``pleats['depth']`` deep (peak to trough):
    z += depth / 2 sin(2 pi count (x - x0) / width) over the curves' x extent. A fold of the flat fabric, not a
    simulated drape: yarns along x follow the wave, yarns along y are lifted whole."""
    if not pleats:
        return cs
    x0 = min(float(np.min(p[:, 0])) for p in cs.points)
    width = max(float(np.max(p[:, 0])) for p in cs.points) - x0
    if not width > 0:
        return cs
    k, half = 2.0 * np.pi * int(pleats["count"]) / width, 0.5 * float(pleats["depth"])
    out = []
    for p in cs.points:
        q = np.array(p, np.float64)
        q[:, 2] += half * np.sin(k * (q[:, 0] - x0))
        out.append(q)
    cs.points = out
    return cs


def generate(gen: dict, yarn_radius: float | None = None) -> CurveSet:
    """The CurveSet of a generator table (module doc), pleated when it says so (``pleated``)."""
    return pleated(_generate(gen, yarn_radius), gen.get("pleats"))


def _generate(gen: dict, yarn_radius: float | None = None) -> CurveSet:
    kind, pattern = gen.get("kind"), gen.get("pattern")
    place = "fabric.generator"
    allowed = {"woven": WOVEN, "knit": KNIT}.get(kind)
    if allowed is None:
        raise LoomError(None, place, f"kind = {kind!r}: expected 'woven' or 'knit'")
    if pattern not in allowed:
        raise LoomError(None, place, f"pattern = {pattern!r} is not a {kind} pattern (one of {', '.join(allowed)})")
    ends, picks = int(gen.get("ends", 16)), int(gen.get("picks", 16))
    spacing = float(gen.get("spacing", 0.1))
    if ends < 1 or picks < 1 or not spacing > 0:
        raise LoomError(None, place, f"ends = {ends}, picks = {picks}, spacing = {spacing}: must be positive")
    radius = gen.get("yarn_radius", yarn_radius)
    try:
        if kind == "woven":
            over = _interlacement(pattern, gen, ends, picks)
            r = float(radius) if radius is not None else spacing / 4.0
            return woven_curveset(over, spacing, spacing, r, r, float(gen.get("crimp", 1.0)),
                                  int(gen.get("samples_per_cell", 6)),
                                  notes={"pattern": pattern, "generator": dict(gen)})
        from stages.ingest import knit

        course = float(gen.get("course_spacing", 0.8 * spacing))
        r = float(radius) if radius is not None else knit.default_radius(spacing, course)
        curves, closed = knit.knit_curves(pattern, ends, picks, spacing, course, r,
                                          int(gen.get("samples_per_cell", 16)))
    except ValueError as e:
        raise LoomError(None, place, str(e)) from None
    points = [curves[i] for i in range(len(curves))]
    return CurveSet(points=points, closed=list(closed), group=["knit"] * len(points),
                    point_radius=[np.full(len(p), r) for p in points], curve_type="catmull-rom",
                    source_format="knit",
                    notes={"pattern": pattern, "generator": dict(gen), "yarn_radius": r,
                           "spacing": (spacing, course)})


def from_wif(path, scale: float = 1.0, crimp: float = 1.0, max_threads: int | None = None, repeat=None,
             samples_per_cell: int = 6) -> CurveSet:
    from stages.ingest.weave import tile

    from .io.wif import parse

    if not scale > 0:
        raise LoomError(path, "fabric.scale", f"scale = {scale} must be positive")
    d = parse(path, scale=scale)
    over, wc, fc = d.over, d.warp_colors, d.weft_colors
    if repeat is not None:
        rx, ry = (int(x) for x in repeat)
        if rx < 1 or ry < 1:
            raise LoomError(path, "fabric.repeat", f"repeat = {list(repeat)} must be >= 1")
        over, wc, fc = tile(over, rx, ry), wc * rx, fc * ry
    if max_threads is not None:
        m = int(max_threads)
        if m < 1:
            raise LoomError(path, "fabric.max_threads", f"max_threads = {m} must be >= 1")
        over, wc, fc = over[:m, :m], wc[:m], fc[:m]
    try:
        return woven_curveset(over, d.warp_spacing, d.weft_spacing, d.warp_radius, d.weft_radius, crimp,
                              samples_per_cell, wc, fc, source="wif",
                              notes={"rising_shed": d.rising, "shafts": d.shafts, "treadles": d.treadles, **d.notes})
    except ValueError as e:
        raise LoomError(path, "fabric", str(e)) from None
