"""Lookup runner: seed 000 Algorithm 1 at the points of a ``.npy`` file, results in a ``.npz``.

``run_lookup(tables, points, out)`` checks the points ((N, 3), numeric, finite), loads the tables
artifact (``pipeline.runners.tables.load_tables``), looks every point up
(``stages.core.yarn.lookup.lookup_points``) and writes inside, yarn, kind, direction, density and
albedo to ``out`` (written beside it, then moved into place).
"""
from __future__ import annotations

from pathlib import Path

POINT_BYTES = 200    # a point: read, as float64, its six results and their copies in the .npz


def _npy_rows(path: Path) -> int:
    """Rows of a .npy array from its header alone (0 when unreadable: np.load says why below)."""
    import numpy as np

    try:
        shape = np.load(path, mmap_mode="r", allow_pickle=False).shape
    except (ValueError, OSError):
        return 0
    return int(shape[0]) if shape else 1


def run_lookup(tables, points: Path, out: Path, budget=None) -> dict:
    """{"inside": points inside a fibre, "points": points looked up}. ``budget`` (``pipeline.memory.budget``):
    refuse before reading the points when they, their results and the loaded tables would exceed it."""
    import numpy as np

    from stages.core.yarn.lookup import lookup_points

    from ..artifacts import Artifact, clean_stale, temp_sibling
    from ..errors import LoomError
    from ..memory import budget as memory_budget
    from .tables import accel_estimate, load_tables

    points, out = Path(points), Path(out)
    if not points.exists():
        raise LoomError(points, None, "file not found")
    clean_stale(out)
    est = accel_estimate(Artifact(tables, kind="tables"), "loomlight lookup")
    n = _npy_rows(points)
    est.add("points", float(POINT_BYTES) * n, f"{n:,} points").check(budget or memory_budget(), points)
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
    tmp = temp_sibling(out)
    np.savez(tmp, inside=res.inside, yarn=res.yarn.astype(np.int64), kind=res.kind.astype(np.int64),
             direction=res.direction, density=res.density, albedo=res.albedo)
    tmp.replace(out)
    return {"inside": int(res.inside.sum()), "points": len(pts)}
