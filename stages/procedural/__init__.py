"""Procedural fibres (seed 000): the yarn model, full realization, realization-minimizing tables
and the point lookups renderers call."""
