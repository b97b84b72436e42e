"""Exemplar tiling and shell mapping (seed 001 §2, §5.1; shell maps of Porumbescu et al. 2005).

``exemplar``       one periodic repeat of a woven fabric as explicit fibres, cut into blocks
``knit_exemplar``  one periodic repeat of a weft knit (stockinette, garter, rib1x1) as explicit fibres
``tiling``         blocks laid over the cloth's (u, v) domain; the block map (damask: one exemplar per block)
``base_surfaces``  flat rectangle, cylinder, a cloth draped over a sphere; smoothed vertex normals
``tetra``          one shell prism -> three tetrahedra; per-tetrahedron affine maps and face planes
``shell``          the shell: base surface offset along its normals, tetrahedra, adjacency, boundary faces
``mapping``        world <-> shell texture coordinates (u, v, w) <-> flat exemplar space
The ray traversal through the shell lives in ``stages.core.shell.traversal`` (precompute reuses it).
"""
