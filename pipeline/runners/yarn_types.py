"""The yarn types of a yarns artifact, resolved against the presets (shared by tables and realize).

``yarn_types_of(yarns, preset, radius)`` gives each yarn type of the artifact's summary its preset
parameters, scaled to ``radius`` or to the median radius of its curves (``pipeline.presets``), packed
for the kernels (``stages.core.yarn.model``), plus every yarn's type index and albedo: its yarn
type's (the preset's, or the scene's ``yarns.<group>.color``), except for a yarn whose colour ingest
took from the draft (``color_source`` = draft, ``pipeline.thread_colors``): that yarn's ``color``.
Every method that reads a woven fabric's colours (tables, realize, bysdf, volpath) gets them here.
``type_summary`` is what the tables and fibers artifacts record of each type.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..artifacts import Artifact
from ..presets import pack, resolve_yarn_types
from ..thread_colors import FROM_DRAFT


class YarnTypes(NamedTuple):
    dicts: list             # resolved preset dicts, one per type
    tparams: np.ndarray     # (T, NPARAM) float64, packed
    yarn_type: np.ndarray   # (Y,) int32, the type of every yarn
    albedo: np.ndarray      # (Y, 3) float64, the albedo of every yarn


def yarn_types_of(yarns: Artifact, preset: str | None, radius: float | None) -> YarnTypes:
    """(type dicts, packed tparams (T, NPARAM), yarn_type (Y,), albedo (Y, 3)) of a yarns artifact."""
    types = yarns.summary.get("yarn_types") or [{}]
    ytype = np.asarray(yarns["yarn_type"], np.int32)
    rad = np.asarray(yarns["radius"], np.float64)
    type_radius = [float(np.median(rad[ytype == t] if (ytype == t).any() else rad)) for t in range(len(types))]
    dicts = resolve_yarn_types(types, type_radius, preset=preset, radius=radius, file=yarns.path)
    tparams = np.stack([pack(d) for d in dicts])
    albedo = np.asarray([dicts[t]["albedo"] for t in ytype], np.float64).reshape(-1, 3)
    if "color_source" in yarns:   # absent in yarns artifacts made before it: every yarn its type's colour
        draft = np.asarray(yarns["color_source"]) == FROM_DRAFT
        albedo[draft] = np.asarray(yarns["color"], np.float64)[draft]
    return YarnTypes(dicts, tparams, ytype, albedo)


def type_summary(dicts):
    keep = ("name", "scale", "ply_num", "fiber_num", "yarn_radius", "fiber_radius", "density", "roughness", "albedo")
    return [{k: d[k] for k in keep if k in d} for d in dicts]
