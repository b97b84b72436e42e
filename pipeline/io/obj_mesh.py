"""OBJ triangle meshes with texture coordinates: the base surface of a tiling (``[surface] kind = "obj"``).

``read_obj_mesh(path, file)`` reads ``v``, ``vt`` and ``f`` lines (faces as ``v/vt`` or ``v/vt/vn``
corners, polygons fanned into triangles, negative indices counted from the end) and returns an
``ObjMesh`` (V, UV, F, and with ``normals=True`` the OBJ's own vertex normals N from its ``vn`` lines)
with a vertex per distinct (v, vt) pair, so vertices split where uv differ. A missing
file is named against ``file`` (the tiling configuration's ``surface.path``); bad lines by number.
The curve reader of ``.obj`` polylines is ``obj.py``.
"""
from __future__ import annotations

from collections import namedtuple
from pathlib import Path

import numpy as np

from ..errors import LoomError

ObjMesh = namedtuple("ObjMesh", ["V", "UV", "F", "N"])
ObjMesh.__doc__ = """read_obj_mesh's mesh: positions V (n, 3), texture coordinates UV (n, 2), triangles F (m, 3) int64,
and, when asked for, the OBJ's own unit normal per vertex N (n, 3) (None when a face corner names none)."""


def read_obj_mesh(path, file, normals: bool = False, uv_for: str = "shell mapping needs uv") -> ObjMesh:
    """The triangle/polygon OBJ mesh with vt at ``path`` (module doc); vertices split where uv differ.
    ``normals``: also the mean of the normals (``vn``) each vertex's corners name, normalised (None when a
    corner names no normal or a mean vanishes; an unreadable ``vn`` line or normal index is refused).
    ``uv_for`` ends the message that refuses a mesh without texture coordinates (who needs them)."""
    p = Path(path)
    if not p.exists():
        raise LoomError(file, "surface.path", f"OBJ file not found: {p}")
    v, vt, vn, faces = [], [], [], []
    has_normals = normals
    for ln, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                v.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                vt.append([float(x) for x in parts[1:3]])
            elif parts[0] == "vn" and normals:
                vn.append(_normal(parts, p, ln))
            elif parts[0] == "f":
                corners = []
                for c in parts[1:]:
                    ids = c.split("/")
                    if len(ids) < 2 or ids[1] == "":
                        raise LoomError(p, f"line {ln}", f"face corner without a texture coordinate (v/vt): {uv_for}")
                    vi, ti = int(ids[0]), int(ids[1])
                    vi = vi - 1 if vi > 0 else len(v) + vi
                    ti = ti - 1 if ti > 0 else len(vt) + ti
                    if not (0 <= vi < len(v)) or not (0 <= ti < len(vt)):
                        raise LoomError(p, f"line {ln}", "face index out of range")
                    ni = -1
                    if has_normals:
                        if len(ids) < 3 or ids[2] == "":
                            has_normals = False
                        else:
                            ni = _normal_index(ids[2], len(vn), p, ln)
                    corners.append((vi, ti, ni))
                if len(corners) < 3:
                    raise LoomError(p, f"line {ln}", "face with fewer than 3 corners")
                for k in range(1, len(corners) - 1):
                    faces.append((corners[0], corners[k], corners[k + 1]))
        except ValueError as e:
            raise LoomError(p, f"line {ln}", f"unreadable number: {e}") from None
    if not faces:
        raise LoomError(p, None, "no faces: shell mapping needs a triangle mesh")
    if not vt:
        raise LoomError(p, None, f"no texture coordinates (vt): {uv_for}")
    key, corner_normals = {}, {}
    F = np.empty((len(faces), 3), np.int64)
    for i, f in enumerate(faces):
        for k, c in enumerate(f):
            F[i, k] = key.setdefault(c[:2], len(key))
            corner_normals.setdefault(c[:2], []).append(c[2])
    pairs = np.array(list(key.keys()), np.int64)
    N = _vertex_normals(vn, corner_normals.values()) if has_normals else None
    return ObjMesh(np.asarray(v, float)[pairs[:, 0]], np.asarray(vt, float)[pairs[:, 1]], F, N)


def _normal(parts, p, ln):
    try:
        n = [float(x) for x in parts[1:4]]
    except ValueError:
        n = []
    if len(n) != 3 or not np.all(np.isfinite(n)):
        raise LoomError(p, f"line {ln}", "unreadable normal (vn x y z) or face corner (v/vt/vn)")
    return n


def _normal_index(text, count, p, ln):
    try:
        ni = int(text)
    except ValueError:
        raise LoomError(p, f"line {ln}", "unreadable normal (vn x y z) or face corner (v/vt/vn)") from None
    ni = ni - 1 if ni > 0 else count + ni
    if not 0 <= ni < count:
        raise LoomError(p, f"line {ln}", "face normal index out of range")
    return ni


def _vertex_normals(vn, per_vertex):
    """Each vertex's normals (indices into vn, one per corner it is) summed and normalised; None where a sum
    vanishes."""
    vn = np.asarray(vn, np.float64)
    N = np.stack([vn[ns].sum(axis=0) for ns in per_vertex])
    length = np.linalg.norm(N, axis=1)
    if np.any(length == 0):
        return None
    return N / length[:, None]
