"""Binary Curve Collection (.bcc): the format of the public yarn-level cloth models.

Layout (little-endian): a 64-byte header — signature ``BCC``, byte count ``0x44`` (int32 and
float32), curve type ``C0`` (uniform Catmull-Rom through the control points) or ``PL``
(polyline), dimensions 3, up axis 0/1/2, uint64 curve count, uint64 total control point count,
40 bytes of free text — then per curve an int32 ``n`` and ``|n|`` float32 xyz points. Negative
``n`` marks a closed curve. The file ends exactly after the last curve.

Up axis. loomlight's fabric space is z-up. A file whose up axis is ``u`` is brought to z-up by
the cyclic permutation that moves axis ``u`` to z:

    z-up (x, y, z) = file (p[(u+1) % 3], p[(u+2) % 3], p[u])

i.e. up 2: (x, y, z) unchanged; up 1 (y-up): (z, x, y); up 0 (x-up): (y, z, x). A cyclic
permutation is a proper rotation (determinant +1), so handedness and curve orientation are
kept and values are moved, never changed (round trips stay bitwise exact). The writer applies
the inverse permutation for the up axis it is asked to store (2 by default).

``read(path)`` -> CurveSet (float32 points, group 'other', source_format 'bcc');
``write(path, curveset, curve_type=None, up_axis=2, text="")``.
Malformed files raise LoomError naming the file and the byte offset or curve/point.
"""
from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from ..curveset import CurveSet
from ..errors import LoomError
from ..limits import coordinate_problem, first_bad_row

HEADER_SIZE = 64
_HEADER = struct.Struct("<3sB2sbbQQ40s")
_CURVE_TYPES = {b"C0": "catmull-rom", b"PL": "polyline"}


def to_z_up(points: np.ndarray, up_axis: int) -> np.ndarray:
    """File coordinates with up axis ``up_axis`` -> z-up (cyclic permutation, a rotation)."""
    order = [(up_axis + 1) % 3, (up_axis + 2) % 3, up_axis]
    return np.ascontiguousarray(points[:, order])


def from_z_up(points: np.ndarray, up_axis: int) -> np.ndarray:
    """Inverse of :func:`to_z_up`: z-up -> file coordinates with up axis ``up_axis``."""
    order = np.argsort([(up_axis + 1) % 3, (up_axis + 2) % 3, up_axis])
    return np.ascontiguousarray(points[:, order])


def read_header(data: bytes, path) -> dict:
    if len(data) < HEADER_SIZE:
        raise LoomError(path, f"byte {len(data)}",
                        f"truncated file: the BCC header needs {HEADER_SIZE} bytes, the file has {len(data)}")
    sig, nbytes, ctype, dims, up, ncurves, npoints, text = _HEADER.unpack_from(data, 0)
    if sig != b"BCC":
        raise LoomError(path, "byte 0", f"wrong signature {sig!r}: not a BCC file (expected b'BCC')")
    if nbytes != 0x44:
        raise LoomError(path, "byte 3",
                        f"unsupported byte count 0x{nbytes:02x}: only 0x44 (int32 and float32) is supported")
    if ctype not in _CURVE_TYPES:
        raise LoomError(path, "byte 4",
                        f"unsupported curve type {ctype!r}: expected b'C0' (Catmull-Rom) or b'PL' (polyline)")
    if dims != 3:
        raise LoomError(path, "byte 6", f"unsupported dimension count {dims}: only 3 is supported")
    if up not in (0, 1, 2):
        raise LoomError(path, "byte 7", f"up axis {up} is not 0, 1 or 2")
    return {"curve_type": _CURVE_TYPES[ctype], "up_axis": int(up), "curve_count": int(ncurves),
            "point_count": int(npoints), "text": text.split(b"\0", 1)[0].decode("latin-1").strip()}


def read(path, group: str = "other", **_ignored) -> CurveSet:
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise LoomError(path, None, f"cannot read: {e.strerror or e}") from None
    head = read_header(data, path)
    size = len(data)
    ncurves = head["curve_count"]
    # every curve takes at least 4 + 2*12 bytes: a header count beyond that cannot be honest
    if ncurves > (size - HEADER_SIZE) // 28 + 1:
        raise LoomError(path, "byte 8", f"header curve count {ncurves} cannot fit in a file of {size} bytes")
    points, closed = [], []
    off = HEADER_SIZE
    total = 0
    for c in range(ncurves):
        if off + 4 > size:
            raise LoomError(path, f"byte {off}: curve {c}",
                            f"the file ends after {c} curves, the header declares {ncurves}")
        n = int(np.frombuffer(data, "<i4", 1, off)[0])
        m = abs(n)
        if m < 2:
            raise LoomError(path, f"byte {off}: curve {c}", f"curve has {m} control points (at least 2 needed)")
        end = off + 4 + 12 * m
        if end > size:
            raise LoomError(path, f"byte {off}: curve {c}",
                            f"point count {n} overruns the file ({12 * m} bytes of points needed, "
                            f"{size - off - 4} left)")
        p = np.frombuffer(data, "<f4", 3 * m, off + 4).reshape(m, 3)
        k = first_bad_row(p)
        if k >= 0:
            raise LoomError(path, f"curve {c}, point {k}", coordinate_problem(p[k].tolist()))
        points.append(to_z_up(p, head["up_axis"]).astype(np.float32, copy=False))
        closed.append(n < 0)
        total += m
        off = end
    if off != size:
        raise LoomError(path, f"byte {off}",
                        f"{size - off} trailing bytes after the {ncurves} curves the header declares")
    if total != head["point_count"]:
        raise LoomError(path, "byte 16",
                        f"header declares {head['point_count']} control points, the curves hold {total}")
    return CurveSet(points=points, closed=closed, group=[group] * ncurves, point_radius=None,
                    curve_type=head["curve_type"], source_format="bcc",
                    notes={"up_axis": head["up_axis"], "text": head["text"]})


def to_bytes(cs: CurveSet, curve_type: str | None = None, up_axis: int = 2, text: str = "") -> bytes:
    ctype = curve_type or cs.curve_type
    code = {"catmull-rom": b"C0", "C0": b"C0", "polyline": b"PL", "PL": b"PL"}.get(ctype)
    if code is None:
        raise ValueError(f"curve type {ctype!r}: expected 'catmull-rom'/'C0' or 'polyline'/'PL'")
    if up_axis not in (0, 1, 2):
        raise ValueError(f"up axis {up_axis} is not 0, 1 or 2")
    parts = []
    total = 0
    for p, cl in zip(cs.points, cs.closed):
        p = np.asarray(p, dtype=np.float32).reshape(-1, 3)
        n = len(p)
        total += n
        parts.append(np.array([-n if cl else n], dtype="<i4").tobytes())
        parts.append(from_z_up(p, up_axis).astype("<f4").tobytes())
    raw_text = text.encode("latin-1", "replace")[:40].ljust(40, b"\0")
    header = _HEADER.pack(b"BCC", 0x44, code, 3, up_axis, len(cs.points), total, raw_text)
    return header + b"".join(parts)


def write(path, cs: CurveSet, curve_type: str | None = None, up_axis: int = 2, text: str = "") -> None:
    """Write ``cs`` (z-up) as BCC storing ``up_axis``; atomic (temporary file, then rename)."""
    path = Path(path)
    blob = to_bytes(cs, curve_type, up_axis, text)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(blob)
    os.replace(tmp, path)
