"""Wavefront OBJ polylines: ``v x y z`` vertices and ``l i j k ...`` line elements.

Reading: indices are 1-based; negative indices count back from the last vertex defined so far
(``-1`` = the latest). Positive indices are resolved against all vertices of the file. An ``l``
whose first and last index are equal is a closed curve (the repeated vertex is dropped).
``l 3/7`` (vertex/texture) uses the vertex part. ``g NAME`` with NAME one of warp, weft, knit,
other sets the yarn group of the following lines (default other). ``#`` starts a comment; other
records (faces, normals, materials) are ignored. Coordinates are taken as z-up fabric space.

Writing: one ``v`` per control point with 9 significant digits of its float32 value (enough to
read back the identical float32), ``g`` per group change, one ``l`` per curve (closed curves
repeat their first index). Per-point radii are not representable in OBJ and are dropped.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..curveset import GROUPS, CurveSet
from ..errors import LoomError
from ..limits import coordinate_problem


def fmt32(x) -> str:
    """The shortest-safe text for a float32: 9 significant digits read back bitwise."""
    return format(float(np.float32(x)), ".9g")


def read(path, **_ignored) -> CurveSet:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise LoomError(path, None, f"cannot read: {e.strerror or e}") from None
    verts: list[tuple[float, float, float]] = []
    lines = []  # (line number, raw indices, count of vertices so far, group)
    group = "other"
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tok = line.split()
        rec = tok[0]
        if rec == "v":
            if len(tok) < 4:
                raise LoomError(path, f"line {lineno}", f"vertex needs 3 coordinates, got {len(tok) - 1}")
            try:
                xyz = tuple(float(t) for t in tok[1:4])
            except ValueError:
                raise LoomError(path, f"line {lineno}", f"bad vertex coordinate in {line!r}") from None
            if not all(math.isfinite(c) for c in xyz):
                raise LoomError(path, f"line {lineno}", f"non-finite vertex coordinate in {line!r}")
            if why := coordinate_problem(xyz):
                raise LoomError(path, f"line {lineno}", why)
            verts.append(xyz)
        elif rec == "l":
            try:
                idx = [int(t.split("/", 1)[0]) for t in tok[1:]]
            except ValueError:
                raise LoomError(path, f"line {lineno}", f"bad vertex index in {line!r}") from None
            lines.append((lineno, idx, len(verts), group))
        elif rec == "g":
            name = tok[1].lower() if len(tok) > 1 else "other"
            group = name if name in GROUPS else "other"
    if not lines:
        raise LoomError(path, None, f"no curves: the file has no 'l' line elements ({len(verts)} 'v' vertices); "
                        "loomlight reads OBJ polylines (v/l records)")
    allv = np.asarray(verts, dtype=np.float32).reshape(-1, 3)
    nv = len(allv)
    points, closed, groups = [], [], []
    for lineno, idx, seen, grp in lines:
        res = []
        for i in idx:
            if i > 0:
                j = i - 1
                ok = i <= nv
            elif i < 0:
                j = seen + i
                ok = j >= 0
            else:
                ok = False
            if not ok:
                have = nv if i > 0 else seen
                raise LoomError(path, f"line {lineno}",
                                f"line element references missing vertex {i} ({have} vertices defined)")
            res.append(j)
        is_closed = len(res) >= 2 and res[0] == res[-1]
        if is_closed:
            res = res[:-1]
        if len(res) < 2:
            raise LoomError(path, f"line {lineno}", f"polyline has {len(res)} distinct vertices (at least 2 needed)")
        points.append(np.ascontiguousarray(allv[res]))
        closed.append(is_closed)
        groups.append(grp)
    return CurveSet(points=points, closed=closed, group=groups, point_radius=None,
                    curve_type="polyline", source_format="obj")


def write(path, cs: CurveSet) -> None:
    """Write ``cs`` as OBJ ``v``/``l`` records; atomic (temporary file, then rename)."""
    path = Path(path)
    out = ["# loomlight yarn curves: v = control point (z-up), l = one curve; first == last index: closed\n"]
    base = 1
    current = None
    for p, cl, grp in zip(cs.points, cs.closed, cs.group):
        p = np.asarray(p, dtype=np.float32).reshape(-1, 3)
        if grp != current:
            out.append(f"g {grp}\n")
            current = grp
        out.extend(f"v {fmt32(x)} {fmt32(y)} {fmt32(z)}\n" for x, y, z in p.tolist())
        idx = list(range(base, base + len(p)))
        if cl:
            idx.append(base)
        out.append("l " + " ".join(map(str, idx)) + "\n")
        base += len(p)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text("".join(out), encoding="utf-8")
    os.replace(tmp, path)
