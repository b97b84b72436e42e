"""The large hostile files, generated rather than checked in (``python tests/hostile/make_large.py DIR``;
the test module calls ``make(tmp_dir)``): the bad value sits at the end of a long, otherwise valid file,
so the readers are seen to check every line and curve, not a prefix.

- ``long_tail.txt``: one 100 000-point curve of 'x y z' lines whose last x is 1e30.
- ``many_curves.bcc``: 10 000 three-point curves whose last curve holds a NaN.
"""
from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np

LONG_TAIL_POINTS = 100_000
MANY_CURVES = 10_000


def make(directory) -> dict[str, Path]:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    n = LONG_TAIL_POINTS
    pts = np.zeros((n, 3))
    pts[:, 0] = np.arange(n) * 1e-3
    pts[:, 2] = 0.01 * (np.arange(n) % 2)
    pts[-1, 0] = 1e30
    long_tail = d / "long_tail.txt"
    long_tail.write_text("".join(f"{x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in pts.tolist()))

    curves = np.zeros((MANY_CURVES, 3, 3), "<f4")
    curves[:, :, 0] = np.arange(3) * 0.1
    curves[:, :, 1] = np.arange(MANY_CURVES)[:, None] * 0.1
    curves[-1, 1, 2] = np.nan
    header = struct.pack("<3sB2sbbQQ40s", b"BCC", 0x44, b"PL", 3, 2, MANY_CURVES, 3 * MANY_CURVES, b"")
    body = b"".join(struct.pack("<i", 3) + c.tobytes() for c in curves)
    many = d / "many_curves.bcc"
    many.write_bytes(header + body)
    return {"long_tail.txt": long_tail, "many_curves.bcc": many}


if __name__ == "__main__":  # pragma: no cover
    for _name, path in make(sys.argv[1] if len(sys.argv) > 1 else ".").items():
        print(path)
