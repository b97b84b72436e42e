"""File-format readers and writers, each ``read(path, **opts) -> CurveSet`` / ``write(path, cs)``.

``read_curves(path, **opts)`` dispatches on the suffix: ``.bcc`` (bcc.py), ``.obj`` (obj.py),
``.txt`` (polyline_txt.py), ``.wif`` (wif.py: a weaving draft woven into warp and weft curves;
opts scale, crimp, max_threads, repeat, samples_per_cell). For curve files ``scale`` (default 1)
multiplies coordinates and radii. An unknown suffix, a missing file or a file without curves raises
LoomError; coordinates beyond +-1e6 scene units are refused (``pipeline.limits``).

Beside the curve formats: ``obj_mesh.py`` (an OBJ triangle mesh with uv, the tile stage's base
surface) and ``mitsuba_txt.py`` (realized fibres as Mitsuba 3 curve text, ``loomlight export``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..curveset import CurveSet
from ..errors import LoomError

SUFFIXES = (".bcc", ".obj", ".txt", ".wif")
WIF_OPTIONS = ("scale", "crimp", "max_threads", "repeat", "samples_per_cell")


def _module(suffix: str):
    if suffix == ".bcc":
        from . import bcc as m
    elif suffix == ".obj":
        from . import obj as m
    else:
        from . import polyline_txt as m
    return m


def read_curves(path, **opts) -> CurveSet:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise LoomError(path, None, f"unknown curve file type {path.suffix!r}: expected one of {', '.join(SUFFIXES)}")
    if not path.is_file():
        raise LoomError(path, None, "is a directory, not a curve file" if path.is_dir() else "no such file")
    if suffix == ".wif":  # a draft, not curves: woven by the generator (the reader here only parses it)
        from ..generators import from_wif

        return from_wif(path, **{k: opts[k] for k in WIF_OPTIONS if k in opts})
    scale = float(opts.pop("scale", 1.0) or 1.0)
    if not scale > 0:
        raise LoomError(path, "scale", f"scale = {scale} must be positive")
    cs = _module(suffix).read(path, **opts)
    if not cs.points:
        raise LoomError(path, None, "no curves: the file holds no control points")
    if scale != 1.0:
        cs.points = [np.asarray(p, dtype=np.float64) * scale for p in cs.points]
        if cs.point_radius is not None:
            cs.point_radius = [np.asarray(r, dtype=np.float64) * scale for r in cs.point_radius]
        cs.notes["scale"] = scale
    return cs


def write_curves(path, cs: CurveSet, **opts) -> None:
    """Write ``cs`` in the format of ``path``'s suffix (.bcc, .obj, .txt)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".bcc", ".obj", ".txt"):
        raise LoomError(path, None, f"cannot write curve file type {path.suffix!r}: expected .bcc, .obj or .txt")
    path.parent.mkdir(parents=True, exist_ok=True)
    _module(suffix).write(path, cs, **opts)
