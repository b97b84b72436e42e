"""A cloth layer's transmittance table: what ``stages.precompute.layer`` measures and ``stages.render.integrators.prt``
reads (the precompute's module doc says what tau is).

``tau`` (2, NB, 3) per exemplar: side (``FROM_ABOVE``: light falling on the top surface, travelling downwards;
``FROM_BELOW``: on the bottom surface), NB bins of cos theta (theta the angle of the light's direction to the
fabric's normal) with centres ``bin_centre(i, NB)`` = (i + 1/2) / NB, RGB. ``tau_at`` interpolates linearly
between the centres and holds the end bins' values beyond them.
"""
import math

from numba import njit

FROM_ABOVE = 0
FROM_BELOW = 1


@njit(cache=True)
def bin_centre(i, nb):
    """cos theta at the centre of bin i of nb."""
    return (i + 0.5) / nb


@njit(cache=True)
def tau_at(tau, side, mu):
    """(r, g, b) of one exemplar's table ``tau`` (2, NB, 3) on ``side`` at cos theta = ``mu`` (0..1)."""
    nb = tau.shape[1]
    x = mu * nb - 0.5
    i0 = min(max(int(math.floor(x)), 0), nb - 1)
    i1 = min(i0 + 1, nb - 1)
    a = min(max(x - i0, 0.0), 1.0)
    t = tau[side]
    return ((1.0 - a) * t[i0, 0] + a * t[i1, 0], (1.0 - a) * t[i0, 1] + a * t[i1, 1],
            (1.0 - a) * t[i0, 2] + a * t[i1, 2])
