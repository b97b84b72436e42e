"""The integrator interface: one estimator of the radiance along a camera ray per render method.

An integrator is a namedtuple class holding everything its estimator reads (geometry or medium,
materials, lights, depth limits, ...). Its module registers, with ``numba.extending.overload``, the
implementation of the generic kernel

    radiance(integ, o, d, seed, index) -> PathSample

for its class (dispatch: ``stages.core.dispatch``): the radiance arriving along the camera ray
(origin o, unit direction d, float64[3] each; the integrator may overwrite them) of camera sample
``index``, whose random numbers are ``uniform(seed, index, dim)`` from dimension 2 on (0 and 1 place
the sample in its pixel). The tile loop (``stages.render.tiles``) is compiled once per integrator
class and is the same for every method: camera, film and threads are not an integrator's business.

``PathSample`` fields: ``r, g, b`` the radiance estimate; ``hit`` 1.0 when the camera ray met the
scene (fibres, medium or ground), else 0.0; ``depth`` the distance to that first interaction (0 when
none); ``lookups`` medium lookups made (0 for surface methods); ``rays`` rays or free-flight queries
traced.

Integrators: ``stages.render.integrators.fiberpath`` (explicit fibre surfaces), ``stages.render.integrators.volpath``
(micro-flake media). A new render method is one such file (namedtuple + estimator + overload), its
registry entry in ``pipeline.renderers`` and its tests.
"""
from collections import namedtuple

PathSample = namedtuple("PathSample", ["r", "g", "b", "hit", "depth", "lookups", "rays"])


def radiance(integ, o, d, seed, index):
    """The integrator's ``PathSample`` for one camera ray; numba-only (overloaded per integrator)."""
    raise TypeError("radiance is only callable from numba-compiled code")
