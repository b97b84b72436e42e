"""Weft-knitted yarn centrelines for the ingest stage's knit generator (``pipeline/generators.py``).

The loop model lives in ``stages.core.curves.knit`` (shared with the tile stage's knitted exemplars);
its docstring gives the parameters and the geometry. ``knit_curves(pattern, wales, courses, w, h, r,
samples_per_stitch=16, tube=False) -> (curves (courses, N, 3), closed (courses,))``, ``stitch_types``,
``default_radius`` and the model's constants are re-exported here unchanged.
"""
from __future__ import annotations

from stages.core.curves.knit import (
                                     DEPTH_FACTOR,
                                     LEAN,
                                     LOOP_HALF_HEIGHT,
                                     PATTERNS,
                                     PLATEAU,
                                     SINKER_CLEARANCE,
                                     default_radius,
                                     knit_curves,
                                     stitch_types,
)

__all__ = ["DEPTH_FACTOR", "LEAN", "LOOP_HALF_HEIGHT", "PATTERNS", "PLATEAU", "SINKER_CLEARANCE", "default_radius",
           "knit_curves", "stitch_types"]
