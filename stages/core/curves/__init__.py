"""Yarn centre curves: ``spline`` (the ``Curves`` layout, Hermite segments, arc length), ``frames``
(rotation-minimising frames), ``closest`` (exact closest points, yarns near a point), ``yarn_space``
(seed 000 Eq. 7-9), ``woven`` (centrelines of a woven fabric from its interlacement) and ``knit`` (the
weft-knit loop model, one curve per course)."""
