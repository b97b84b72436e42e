"""volpath's media: the density sources it tracks through, and the tracking itself.

``medium``             the density-source interface (``medium_lookup``), a homogeneous box
``tracking``           majorant grids, delta and ratio tracking
``procedural_medium``  seed 000's lookups on the fly
``realized_medium``    realized fibres in a BVH
``grid_medium``        a voxel grid (and ``voxelize``, which makes one)
``fibre_cache``        the render-time fibre cache: procedural bricks the camera sees, realized into a BVH
"""
