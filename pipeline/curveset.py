"""In-memory yarn curves as readers and generators hand them to the ingest stage."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GROUPS = ("warp", "weft", "knit", "other")


@dataclass
class CurveSet:
    """Curves as read or generated, before spline processing.

    points:        one (n_i, 3) float array per curve (control points, z-up fabric space)
    closed:        per curve: True where the curve loops (BCC negative count)
    point_radius:  per curve (n_i,) radii, or None where the source gives none
    group:         per curve one of GROUPS
    color:         per curve linear RGB in [0, 1], or None for the yarn type's colour
    curve_type:    'catmull-rom' (interpolating spline) or 'polyline' (BCC PL, OBJ, text: still
                   splined by ingest, since seed 000 §5.1 needs C1 frames; recorded for writers)
    source_format: 'bcc', 'obj', 'txt', 'wif', 'woven', 'knit'
    """

    points: list[np.ndarray]
    closed: list[bool]
    group: list[str]
    point_radius: list[np.ndarray] | None = None
    color: list[tuple[float, float, float] | None] = field(default_factory=list)
    curve_type: str = "catmull-rom"
    source_format: str = ""
    notes: dict = field(default_factory=dict)

    def __post_init__(self):
        n = len(self.points)
        if not self.color:
            self.color = [None] * n
        assert len(self.closed) == n and len(self.group) == n and len(self.color) == n
