"""Precomputed light transport for fabrics (seed 001 §4): what a shell-mapped exemplar's fibres
need before the ``prt`` method can render them.

``periodic``  rays through the flat fabric made of one exemplar repeated without end (x, y periodic)
``svf``       segment visibility functions: binary visibility images, SSDFs, their PCA, sums of SGs (§4.1)
``iirtf``     mean free path, cells, per-cell SH transfer matrices A_C by Monte Carlo (§4.2)
The SH / SG / BCSDF-expansion math lives in ``stages.core.sh``, ``stages.core.sg`` and
``stages.core.shading.bcsdf_sh`` (the renderer needs it too).
"""
