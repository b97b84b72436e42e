"""Loading the ``yarns`` artifact into the ``Curves`` namedtuple the kernels take."""
from __future__ import annotations

import numpy as np

from stages.core.curves.spline import Curves

from .artifacts import Artifact

GROUP_NAMES = ("warp", "weft", "knit", "other")
CURVE_ARRAYS = ("points", "tangents", "curve_offsets", "closed", "seg_curve", "seg_length", "seg_arclen",
                "curve_length", "frame_s", "frame_offsets", "frame_normal", "frame_twist", "radius", "delta",
                "grid_lo", "grid_cell", "grid_dims", "grid_cell_start", "grid_items", "grid_pad")


def curves_from_group(get) -> Curves:
    """Build ``Curves`` from a getter name -> array (an artifact, a zarr group or a dict)."""
    def f64(n):
        return np.ascontiguousarray(get(n), dtype=np.float64)
    return Curves(
        f64("points"), f64("tangents"), np.ascontiguousarray(get("curve_offsets"), np.int64),
        np.ascontiguousarray(get("closed"), np.bool_), np.ascontiguousarray(get("seg_curve"), np.int32),
        f64("seg_length"), f64("seg_arclen"), f64("curve_length"), f64("frame_s"),
        np.ascontiguousarray(get("frame_offsets"), np.int64), f64("frame_normal"), f64("frame_twist"),
        f64("radius"), f64("delta"), f64("grid_lo"), f64("grid_cell"),
        np.ascontiguousarray(get("grid_dims"), np.int64), np.ascontiguousarray(get("grid_cell_start"), np.int64),
        np.ascontiguousarray(get("grid_items"), np.int32), f64("grid_pad"),
    )


def load_curves(art: Artifact | str) -> Curves:
    if not isinstance(art, Artifact):
        art = Artifact(art, kind="yarns")
    return curves_from_group(lambda n: art[n])
