"""OBJ triangle meshes with texture coordinates: the base surface of a tiling (``[surface] kind = "obj"``).

``read_obj_mesh(path, file)`` reads ``v``, ``vt`` and ``f`` lines (faces as ``v/vt`` or ``v/vt/vn``
corners, polygons fanned into triangles, negative indices counted from the end) and returns
(V, UV, F) with a vertex per distinct (v, vt) pair, so vertices split where uv differ. A missing
file is named against ``file`` (the tiling configuration's ``surface.path``); bad lines by number.
The curve reader of ``.obj`` polylines is ``obj.py``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import LoomError


def read_obj_mesh(path, file):
    """(V, UV, F) of a triangle/polygon OBJ mesh with vt; vertices split where uv differ."""
    p = Path(path)
    if not p.exists():
        raise LoomError(file, "surface.path", f"OBJ file not found: {p}")
    v, vt, faces = [], [], []
    for ln, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                v.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                vt.append([float(x) for x in parts[1:3]])
            elif parts[0] == "f":
                corners = []
                for c in parts[1:]:
                    ids = c.split("/")
                    if len(ids) < 2 or ids[1] == "":
                        raise LoomError(p, f"line {ln}", "face corner without a texture coordinate (v/vt): "
                                                         "shell mapping needs uv")
                    vi, ti = int(ids[0]), int(ids[1])
                    vi = vi - 1 if vi > 0 else len(v) + vi
                    ti = ti - 1 if ti > 0 else len(vt) + ti
                    if not (0 <= vi < len(v)) or not (0 <= ti < len(vt)):
                        raise LoomError(p, f"line {ln}", "face index out of range")
                    corners.append((vi, ti))
                if len(corners) < 3:
                    raise LoomError(p, f"line {ln}", "face with fewer than 3 corners")
                for k in range(1, len(corners) - 1):
                    faces.append((corners[0], corners[k], corners[k + 1]))
        except ValueError as e:
            raise LoomError(p, f"line {ln}", f"unreadable number: {e}") from None
    if not faces:
        raise LoomError(p, None, "no faces: shell mapping needs a triangle mesh")
    if not vt:
        raise LoomError(p, None, "no texture coordinates (vt): shell mapping needs uv")
    key = {}
    F = np.empty((len(faces), 3), np.int64)
    for i, f in enumerate(faces):
        for k, c in enumerate(f):
            F[i, k] = key.setdefault(c, len(key))
    pairs = np.array(list(key.keys()), np.int64)
    return np.asarray(v, float)[pairs[:, 0]], np.asarray(vt, float)[pairs[:, 1]], F
