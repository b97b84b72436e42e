"""Lookup runner: seed 000 Algorithm 1 at the points of a ``.npy`` file, results in a ``.npz``.

``run_lookup(tables, points, out)`` checks the points ((N, 3), numeric, finite), loads the tables
artifact (``pipeline.runners.tables.load_tables``), looks every point up
(``stages.core.yarn.lookup.lookup_points``) and writes inside, yarn, kind, direction, density and
albedo to ``out`` (written beside it, then moved into place).
"""
from __future__ import annotations

from pathlib import Path


def run_lookup(tables, points: Path, out: Path) -> dict:
    """{"inside": points inside a fibre, "points": points looked up}."""
    import numpy as np

    from ..errors import LoomError
    from .tables import load_tables
    from stages.core.yarn.lookup import lookup_points

    points, out = Path(points), Path(out)
    if not points.exists():
        raise LoomError(points, None, "file not found")
    try:
        pts = np.load(points, allow_pickle=False)
    except (ValueError, OSError) as e:
        raise LoomError(points, None, f"not a .npy array: {e}") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.dtype.kind not in "fiu":
        raise LoomError(points, None, f"expected an (N, 3) numeric array, got {pts.dtype} {pts.shape}")
    if not np.isfinite(pts).all():
        raise LoomError(points, f"row {int(np.argmax(~np.isfinite(pts).all(axis=1)))}", "non-finite coordinate")
    cv, tab, _ = load_tables(tables)
    res = lookup_points(cv, tab, np.ascontiguousarray(pts, np.float64))
    if out.suffix != ".npz":
        raise LoomError(out, None, "the output file must end in .npz")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp.npz")
    np.savez(tmp, inside=res.inside, yarn=res.yarn.astype(np.int64), kind=res.kind.astype(np.int64),
             direction=res.direction, density=res.density, albedo=res.albedo)
    tmp.replace(out)
    return {"inside": int(res.inside.sum()), "points": len(pts)}
