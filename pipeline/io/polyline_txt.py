"""Plain-text polylines (the Mitsuba 3 ``linearcurve``/``bsplinecurve`` curve file).

One control point per line, ``x y z`` or ``x y z r`` (r = radius), whitespace separated; a blank
line ends a curve (several blank lines count as one); ``#`` starts a comment (a comment-only line
is not a curve break). Within a curve every line has the same column count, and all curves of a
file agree on whether there is a radius column (CurveSet keeps radii for all curves or none).
A curve whose first and last points are identical (bitwise, three or more points) is read as a
closed curve without the repeated point; the writer repeats the first point of closed curves,
so Mitsuba 3 draws them closed too. Coordinates are taken as z-up fabric space.

Writing: 9 significant digits of each float32 value (read back bitwise); the radius column is
written when the CurveSet has per-point radii, or all points get ``radius`` when given.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..curveset import CurveSet
from ..errors import LoomError
from ..limits import MAX_LENGTH, coordinate_problem
from .obj import fmt32


def read(path, group: str = "other", **_ignored) -> CurveSet:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise LoomError(path, None, f"cannot read: {e.strerror or e}") from None
    curves: list[tuple[int, list[list[float]]]] = []  # (first line, rows)
    cur: list[list[float]] = []
    cur_start = 0
    ncols_file = None
    ncols_cur = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        if not raw.strip():
            if cur:
                curves.append((cur_start, cur))
                cur, ncols_cur = [], None
            continue
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tok = line.split()
        if len(tok) not in (3, 4):
            raise LoomError(path, f"line {lineno}", f"expected 'x y z' or 'x y z r', got {len(tok)} values")
        try:
            row = [float(t) for t in tok]
        except ValueError:
            bad = next(t for t in tok if not _is_float(t))
            raise LoomError(path, f"line {lineno}", f"bad number {bad!r}") from None
        if not all(math.isfinite(v) for v in row):
            raise LoomError(path, f"line {lineno}", f"non-finite value in {line!r}")
        if ncols_cur is not None and len(row) != ncols_cur:
            raise LoomError(path, f"line {lineno}",
                            f"{len(row)} columns inside a curve whose earlier points have {ncols_cur} "
                            "(mixed 3/4 columns)")
        if ncols_file is not None and len(row) != ncols_file:
            raise LoomError(path, f"line {lineno}",
                            f"{len(row)} columns, but earlier curves have {ncols_file}: "
                            "radius column must be all or none")
        if not cur:
            cur_start = lineno
        ncols_cur = ncols_file = len(row)
        if len(row) == 4 and row[3] <= 0:
            raise LoomError(path, f"line {lineno}", f"radius {row[3]} is not positive")
        if len(row) == 4 and row[3] > MAX_LENGTH:
            raise LoomError(path, f"line {lineno}", f"radius {row[3]:g} is beyond {MAX_LENGTH:g} scene units")
        if why := coordinate_problem(row[:3]):
            raise LoomError(path, f"line {lineno}", why)
        cur.append(row)
    if cur:
        curves.append((cur_start, cur))
    points, closed, radii = [], [], []
    for start, rows in curves:
        a = np.asarray(rows, dtype=np.float32)
        is_closed = len(a) >= 3 and bool(np.array_equal(a[0], a[-1]))
        if is_closed:
            a = a[:-1]
        if len(a) < 2:
            raise LoomError(path, f"line {start}", f"curve has {len(a)} points (at least 2 needed)")
        points.append(np.ascontiguousarray(a[:, :3]))
        closed.append(is_closed)
        if a.shape[1] == 4:
            radii.append(np.ascontiguousarray(a[:, 3]))
    return CurveSet(points=points, closed=closed, group=[group] * len(points),
                    point_radius=radii if ncols_file == 4 else None,
                    curve_type="polyline", source_format="txt")


def _is_float(t: str) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def write(path, cs: CurveSet, radius: float | None = None) -> None:
    """Write ``cs`` as a curve text file; atomic (temporary file, then rename)."""
    path = Path(path)
    out = ["# loomlight yarn curves: x y z [r] per control point, blank line between curves\n"]
    for c, (p, cl) in enumerate(zip(cs.points, cs.closed)):
        p = np.asarray(p, dtype=np.float32).reshape(-1, 3)
        r = None
        if cs.point_radius is not None:
            r = np.asarray(cs.point_radius[c], dtype=np.float32)
        elif radius is not None:
            r = np.full(len(p), radius, dtype=np.float32)
        idx = list(range(len(p))) + ([0] if cl else [])
        if c:
            out.append("\n")
        for i in idx:
            s = " ".join(fmt32(v) for v in p[i].tolist())
            if r is not None:
                s += " " + fmt32(r[i])
            out.append(s + "\n")
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text("".join(out), encoding="utf-8")
    os.replace(tmp, path)
