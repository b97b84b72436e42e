"""Export runner: the realized fibres of a ``fibers`` artifact for other renderers.

``run_export(fibers, out)`` writes ``.txt`` as Mitsuba 3 curve text (``pipeline.io.mitsuba_txt``,
written beside the output, then moved into place) or ``.bcc`` as a polyline Binary Curve
Collection (``pipeline.io.bcc``); any other suffix is refused.
"""
from __future__ import annotations

from pathlib import Path

VERTEX_BYTES = 360   # a vertex: read, as float64 rows, as Python floats and text lines (Mitsuba) or curves (BCC)
FIBER_BYTES = 200    # a fibre: its curve array or end index, Python objects


def run_export(fibers, out: Path, budget=None) -> dict:
    """{"curves": fibres written}. ``budget`` (``pipeline.memory.budget``): refuse before reading the fibres
    when writing them would exceed it."""
    import numpy as np

    from ..artifacts import Artifact, clean_stale, temp_sibling
    from ..curveset import CurveSet
    from ..errors import LoomError
    from ..io import bcc
    from ..io.mitsuba_txt import write_mitsuba_txt
    from ..memory import Estimate, budget as memory_budget

    out = Path(out)
    art = Artifact(fibers, kind="fibers")
    shapes = {k: a.shape[0] for k, a in art.arrays().items()}
    V, F = shapes.get("points", 0), max(0, shapes.get("fiber_offsets", 1) - 1)
    Estimate("loomlight export").add("fibres", float(VERTEX_BYTES) * V + float(FIBER_BYTES) * F,
                                     f"{V:,} vertices, {F:,} fibres").check(budget or memory_budget(), fibers)
    pts = np.asarray(art["points"], np.float32)
    rad = np.asarray(art["point_radius"], np.float32)
    off = np.asarray(art["fiber_offsets"], np.int64)
    suffix = out.suffix.lower()
    if suffix not in (".txt", ".bcc"):
        raise LoomError(out, None, "the output must end in .txt (Mitsuba curves) or .bcc")
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".txt":
        clean_stale(out)
        tmp = temp_sibling(out)
        write_mitsuba_txt(tmp, pts, rad, off)
        tmp.replace(out)
    else:
        curves = [pts[off[f]:off[f + 1]] for f in range(len(off) - 1)]
        cs = CurveSet(points=curves, closed=[False] * len(curves), group=["other"] * len(curves),
                      curve_type="polyline", source_format="bcc")
        bcc.write(out, cs, curve_type="polyline", text="loomlight realized fibres")
    return {"curves": len(off) - 1}
