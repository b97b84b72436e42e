"""The render stage, one concept per module.

The skeleton every method shares:
``camera``       perspective pinhole camera (Mitsuba 3 conventions)
``film``         image tiles, per-pixel sums, finalize (mean, alpha, depth, variance of the mean)
``tiles``        the one tile loop (camera samples -> integrator -> film) and its threads
``integrator``   the interface: ``radiance(integ, o, d, seed, index) -> PathSample``
``lights``       distant lights: directional, constant, spherical Gaussian, lat-long envmap
``ground``       the optional Lambertian ground plane

Integrators:
``fiberpath``    explicit fibre surfaces (realized or shell-mapped), BCSDF or Lambert materials
``volpath``      micro-flake media by delta / ratio tracking

volpath's media:
``medium``             the density-source interface (``medium_lookup``), a homogeneous box
``tracking``           majorant grids, delta and ratio tracking
``procedural_medium``  seed 000's lookups on the fly
``realized_medium``    realized fibres in a BVH
``grid_medium``        a voxel grid (and ``voxelize``, which makes one)
Scattering models and geometry queries are in ``stages.core.shading`` and ``stages.core.geometry``.
"""
