"""OBJ triangle meshes: the base surface of a tiling (``[surface] kind = "obj"``, with texture coordinates)
and a scene's ``[[meshes]]`` (walls, floor, furniture: positions and faces only).

``read_obj_mesh(path, file)`` reads ``v``, ``vt`` and ``f`` lines (faces as ``v/vt`` or ``v/vt/vn``
corners, polygons fanned into triangles, negative indices counted from the end) and returns an
``ObjMesh`` (V, UV, F, and with ``normals=True`` the OBJ's own vertex normals N from its ``vn`` lines)
with a vertex per distinct (v, vt) pair, so vertices split where uv differ. With ``uv_for=None`` texture
coordinates are not needed: corners may be ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``, ``vt`` is ignored,
F indexes the file's own vertices and UV is None. A missing file is named against ``file`` at ``place``
(the tiling configuration's ``surface.path``, a scene's ``meshes[i].file``); bad lines by number (a
vertex with fewer than three coordinates or a non-finite one, an index out of range, a face of fewer than
three corners), a file without faces as a whole. The curve reader of ``.obj`` polylines is ``obj.py``.
"""
from __future__ import annotations

from collections import namedtuple
from pathlib import Path

import numpy as np

from ..errors import LoomError

ObjMesh = namedtuple("ObjMesh", ["V", "UV", "F", "N"])
ObjMesh.__doc__ = """read_obj_mesh's mesh: positions V (n, 3), texture coordinates UV (n, 2) (None when not asked for),
triangles F (m, 3) int64,
and, when asked for, the OBJ's own unit normal per vertex N (n, 3) (None when a face corner names none)."""


def read_obj_mesh(path, file, normals: bool = False, uv_for: str | None = "shell mapping needs uv",
                  place: str = "surface.path", faces_for: str = "shell mapping needs a triangle mesh") -> ObjMesh:
    """The triangle/polygon OBJ mesh at ``path`` (module doc); vertices split where uv differ.
    ``normals``: also the mean of the normals (``vn``) each vertex's corners name, normalised (None when a
    corner names no normal or a mean vanishes; an unreadable ``vn`` line or normal index is refused).
    ``uv_for`` ends the message that refuses a mesh without texture coordinates (who needs them); None:
    uv not needed (module doc). ``place`` is the key of ``file`` that names the OBJ, ``faces_for`` ends the
    message that refuses a file without faces."""
    p = Path(path)
    if not p.is_file():
        raise LoomError(file, place, f"OBJ file not found: {p}" if not p.exists() else f"{p} is not a file")
    uv = uv_for is not None
    v, vt, vn, faces = [], [], [], []
    has_normals = normals
    for ln, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                v.append(_vertex(parts, p, ln))
            elif parts[0] == "vt" and uv:
                vt.append([float(x) for x in parts[1:3]])
            elif parts[0] == "vn" and normals:
                vn.append(_normal(parts, p, ln))
            elif parts[0] == "f":
                corners = []
                for c in parts[1:]:
                    ids = c.split("/")
                    if uv and (len(ids) < 2 or ids[1] == ""):
                        raise LoomError(p, f"line {ln}", f"face corner without a texture coordinate (v/vt): {uv_for}")
                    vi = int(ids[0])
                    vi = vi - 1 if vi > 0 else len(v) + vi
                    ti = -1
                    if uv:
                        ti = int(ids[1])
                        ti = ti - 1 if ti > 0 else len(vt) + ti
                    if not (0 <= vi < len(v)) or (uv and not 0 <= ti < len(vt)):
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
        raise LoomError(p, None, f"no faces: {faces_for}")
    if uv and not vt:
        raise LoomError(p, None, f"no texture coordinates (vt): {uv_for}")
    key, corner_normals = {}, {}
    F = np.empty((len(faces), 3), np.int64)
    for i, f in enumerate(faces):
        for k, c in enumerate(f):
            F[i, k] = key.setdefault(c[:2], len(key))
            corner_normals.setdefault(c[:2], []).append(c[2])
    pairs = np.array(list(key.keys()), np.int64)
    N = _vertex_normals(vn, corner_normals.values()) if has_normals else None
    UV = np.asarray(vt, float)[pairs[:, 1]] if uv else None
    return ObjMesh(np.asarray(v, float).reshape(-1, 3)[pairs[:, 0]], UV, F, N)


def _vertex(parts, p, ln):
    xyz = [float(x) for x in parts[1:4]]
    if len(xyz) != 3 or not np.all(np.isfinite(xyz)):
        raise LoomError(p, f"line {ln}", "a vertex needs three finite coordinates (v x y z)")
    return xyz


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
