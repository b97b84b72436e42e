"""The render stage, one concept per module.

The skeleton every method shares:
``camera``       perspective pinhole camera (Mitsuba 3 conventions)
``film``         image tiles, per-pixel sums, finalize (mean, alpha, depth, variance of the mean)
``tiles``        the one tile loop (camera samples -> integrator -> film) and its threads
``integrator``   the interface: ``radiance(integ, o, d, seed, index) -> PathSample``
``lights``       distant lights: directional, constant, spherical Gaussian, lat-long envmap
``ground``       the optional Lambertian ground plane

``integrators/``  one integrator per method (fiberpath, volpath, prt, btf, bysdf; its own docstring lists them)
``media/``        volpath's density sources and the tracking through them
The yarn tubes and implicit plies the bysdf integrator walks live beside the yarn model
(``stages.core.yarn.tubes``, ``.shading_points``, ``.implicit_plies``).
Scattering models and geometry queries are in ``stages.core.shading`` and ``stages.core.geometry``.
"""
