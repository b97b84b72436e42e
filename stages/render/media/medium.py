"""The anisotropic micro-flake medium: what a density source must answer.

Seed 000 App. A: at a point p a textile model gives a density den(p), a fibre direction dir(p), a
roughness sigma(p) and an albedo alpha(p). The micro-flake model (Jakob et al. 2010) with a fibre-like
SGGX distribution S(dir, sigma) (``stages.core.shading.sggx``) turns them into

    sigma_t(p, w) = den(p) * sigma_S(w)         (Jakob 2010 Eq. 8; sigma_S(w) = sqrt(w^T S w) <= 1)
    sigma_s(p, w) = alpha(p) * sigma_t(p, w)     (RGB single-scattering albedo per yarn)
    f_p(wi, wo)   = specular micro-flake phase function of S

Extinction is grey (density times projected area) and only the albedo is RGB, so one free-flight
distance serves all three channels. Because sigma_S(w) <= 1, den(p) itself bounds sigma_t in
every direction: a majorant for den bounds the extinction.

A *density source* is a namedtuple class whose numba implementation of
``medium_lookup(med, x, y, z, skip)`` is registered with ``register_medium`` (``numba.extending.overload``);
it returns a ``MediumPoint``

    (den, tx, ty, tz, albedo_r, albedo_g, albedo_b, roughness, yarn, fibre)

(float64 but for the int64 yarn and fibre: the covering fibre's yarn and a number that tells the
fibres apart, -1 where the source does not know them) with den = 0 outside every fibre
(``NO_MEDIUM``; other fields then unused). ``skip`` is such a fibre number (-1: none) whose fibre
counts as empty: where it and others cover the point, the first of the others in the source's order
answers. A ray leaving a fibre that scattered it as a whole meets every fibre but that one, so a
fibre overlapping it stays solid (fiberpath's rays meet it too), and the fibres' overlaps, a third of
the covered volume at packing 0.5, are no holes. The integrator (``stages.render.integrators.volpath``) is
compiled once per source class. Sources: ``HomogeneousMedium`` (below; a box of constant fibre
material, for closed-form tests), ``stages.render.media.grid_medium``, ``stages.render.media.procedural_medium``,
``stages.render.media.realized_medium``.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.shading.sggx import fiber_sggx, projected_area

MediumPoint = namedtuple("MediumPoint", ["den", "tx", "ty", "tz", "albedo_r", "albedo_g", "albedo_b", "roughness",
                                         "yarn", "fibre"])
MediumPoint.__doc__ = """A density source's answer at a point: density, unit fibre tangent, RGB albedo, SGGX roughness,
the yarn the covering fibre belongs to and a number telling the covering fibres apart (-1 both where
the source does not know them: voxels, boxes)."""
NO_MEDIUM = MediumPoint(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, np.int64(-1), np.int64(-1))  # outside every fibre
# a source that cannot answer yet (paged procedural tables whose yarn's frame samples are not resident:
# stages.core.yarn.frame_pool) answers PAGED_OUT. Tracking takes it as empty, so the ray's later lookups ask
# for their yarns in the same round; a delta-tracked ray that met one ends at its next collision or exit with
# PAGED_OUT as its point, and the integrator ends the path there (yarn PAGED_OUT_YARN): the pixel is rendered
# again once the yarns are in, so nothing after the first miss counts
PAGED_OUT_YARN = -2
PAGED_OUT = MediumPoint(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, np.int64(PAGED_OUT_YARN), np.int64(-1))


def medium_lookup(med, x, y, z, skip):
    """``MediumPoint`` at (x, y, z) of the fibres but ``skip`` (module doc); numba-only (overloaded per
    source)."""
    raise TypeError("medium_lookup is only callable from numba-compiled code")


def register_medium(cls, lookup, knows_fibres=True):
    """Overloads ``medium_lookup`` for density sources of namedtuple class ``cls`` with the kernel
    ``lookup(med, x, y, z, skip)``; ``knows_fibres`` False: ``lookup(med, x, y, z)``, a source with no fibres
    to tell apart (voxels, boxes), which ignores ``skip``."""
    @overload(medium_lookup)
    def _medium_lookup(med, x, y, z, skip):
        if is_tuple_class(med, cls):
            if knows_fibres:
                return lambda med, x, y, z, skip: lookup(med, x, y, z, skip)
            return lambda med, x, y, z, skip: lookup(med, x, y, z)


@njit(cache=True)
def outside_box(lo, hi, x, y, z):
    """True where (x, y, z) lies outside the box [lo, hi]."""
    return x < lo[0] or x > hi[0] or y < lo[1] or y > hi[1] or z < lo[2] or z > hi[2]


@njit(cache=True)
def extinction(den, tx, ty, tz, roughness, wx, wy, wz):
    """sigma_t(w) = den * sigma_S(w) for the fibre-like SGGX of (t, roughness)."""
    if den <= 0.0:
        return 0.0
    return den * projected_area(fiber_sggx(tx, ty, tz, roughness), wx, wy, wz)


# ------------------------------------------------------------------------------------------------
HomogeneousMedium = namedtuple("HomogeneousMedium", ["lo", "hi", "density", "tangent", "roughness", "albedo"])
HomogeneousMedium.__doc__ = """A box [lo, hi] of constant density, fibre tangent, roughness and RGB albedo.

lo, hi, tangent, albedo: float64[3]; density, roughness: float. With roughness = 1 the flakes are
isotropic (sigma_t = density in every direction), the textbook homogeneous medium.
"""


@njit(cache=True)
def homogeneous_lookup(med, x, y, z):
    if outside_box(med.lo, med.hi, x, y, z):
        return NO_MEDIUM
    t = med.tangent
    a = med.albedo
    return MediumPoint(np.float64(med.density), np.float64(t[0]), np.float64(t[1]), np.float64(t[2]),
                       np.float64(a[0]), np.float64(a[1]), np.float64(a[2]), np.float64(med.roughness), np.int64(-1),
                       np.int64(-1))


register_medium(HomogeneousMedium, homogeneous_lookup, knows_fibres=False)
