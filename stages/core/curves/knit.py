"""Weft-knitted yarn centrelines from a parametric loop model: one curve per course.

Shared by the ingest stage's knit generator (``stages.ingest.knit`` re-exports it) and the tile
stage's knitted exemplars (``stages.tile.knit_exemplar``: the same curves over a 3 x 3 patch of
repeats, of which the middle one is periodic).

Parameters: ``pattern`` stockinette | garter | rib1x1, ``wales`` (stitches per course),
``courses``, wale spacing ``w``, course spacing ``h``, yarn radius ``r``, ``samples_per_stitch``
(control points per stitch, >= 8), ``tube`` (circular knitting: each course is a closed ring).

Loop model (t = j + u runs along course i, stitch j, u in [0, 1); w, h in scene units):

    x(t) = w (t + a sin(4 pi t))          a = 0.15: necks (u ~ 1/8, 7/8) pulled towards the wale
                                           centre, shoulders (u ~ 3/8, 5/8) pushed out: the head
                                           is wider than the neck, the legs lean out (the V)
    y(t) = h i - c cos(2 pi t)            c = 1.1 h: the head of course i (u = 1/2, y = h i + c)
                                           reaches above the necks of course i+1, so the new loop
                                           passes through it
    z(t): half-cosine blend between key depths at
          u = 0 .. p (sinker, p = 0.12): -d (k[i, j-1] + k[i, j]) / 2, deepened by 2 r where the
                                         sinker passes legs of the other side (garter)
          u = 1/4, 3/4 (legs):           +d k[i, j]
          u = 1/2 (head):                -d k[i+1, j]   (the stitch drawn through the head
                                                          decides its side)

with d = 3 r and k = +1 for a knit stitch, -1 for a purl stitch. Interlocking: in the
projection onto the fabric plane, course i+1 crosses each loop of course i four times, passing
under its legs (at the sinker), over its head, over its head, under its legs for a knit stitch
(the new loop is pulled through from back to front), the reverse for a purl stitch.
stockinette: k = +1 everywhere; garter: k alternates by course; rib1x1: k alternates by wale
(between a knit and a purl wale the sinker passes through the fabric, z = 0).
These constants were chosen so that, at the default radius (0.06 w for h = 0.8 w), centrelines
of different courses stay more than 1.4 r apart (tests/ingest/test_generators.py measures it).

Open courses run from the sinker before stitch 0 to the sinker after stitch wales-1
(wales * s + 1 points, s = samples_per_stitch). With ``tube`` the course wraps around a cylinder
of circumference wales * w about the y axis (the loop depth becomes a radial offset) and is
closed (wales * s points). The curve never stops (x' > 0 wherever y' = 0), so consecutive
points never coincide.

Returns (curves (courses, N, 3) float64, closed (courses,) bool).
"""
from __future__ import annotations

import numpy as np

LEAN = 0.15          # a: x(t) = w (t + a sin 4 pi t); > 1/(4 pi): legs lean back (loop shape)
LOOP_HALF_HEIGHT = 1.1   # c / h
DEPTH_FACTOR = 3.0   # d / r
SINKER_CLEARANCE = 2.0  # extra sinker depth (yarn radii) where it passes legs of the other side
PLATEAU = 0.12       # the sinker depth holds for u in [-PLATEAU, PLATEAU] around each sinker
PATTERNS = ("stockinette", "garter", "rib1x1")


def stitch_types(pattern: str, wales: int, courses: int) -> np.ndarray:
    """(courses, wales) int: +1 knit, -1 purl."""
    i = np.arange(courses)[:, None]
    j = np.arange(wales)[None, :]
    if pattern == "stockinette":
        k = np.ones((courses, wales), dtype=np.int64)
    elif pattern == "garter":
        k = np.where(i % 2 == 0, 1, -1) + 0 * j
    elif pattern == "rib1x1":
        k = np.where(j % 2 == 0, 1, -1) + 0 * i
    else:
        raise ValueError(f"knit pattern {pattern!r}: expected one of {', '.join(PATTERNS)}")
    return k.astype(np.int64)


def default_radius(w: float, h: float) -> float:
    """A yarn radius the loop model holds without gross interpenetration (see tests)."""
    return 0.06 * min(w, h / 0.8)


def _depth_keys(k: np.ndarray, d: float, clear: float, tube: bool):
    """Key positions (6 W + 1,) along the course and key depths (courses, 6 W + 1): per stitch
    u = 0 and PLATEAU (sinker), 1/4 (leg), 1/2 (head), 3/4 (leg), 1 - PLATEAU (sinker)."""
    C, W = k.shape
    nxt = np.vstack([k[1:], k[-1:]])                      # the course drawn through this one
    below = np.vstack([k[:1], k[:-1]])                    # the course this one is drawn through
    if tube:
        kl, kr = np.roll(k, 1, axis=1), k
        bl, br = np.roll(below, 1, axis=1), below
        kl, kr, bl, br = (np.hstack([a, a[:, :1]]) for a in (kl, kr, bl, br))
    else:                                                 # edge sinkers take their stitch's side
        kl, kr = np.hstack([k[:, :1], k]), np.hstack([k, k[:, -1:]])
        bl, br = np.hstack([below[:, :1], below]), np.hstack([below, below[:, -1:]])
    m, m_below = (kl + kr) / 2.0, (bl + br) / 2.0
    # sinker j (left of stitch j, j = 0..W): a sinker passing legs of the other side (garter)
    # goes a further `clear` beyond them
    sink = -(d + np.where(m * m_below < 0, clear, 0.0)) * m
    u = np.array([0.0, PLATEAU, 0.25, 0.5, 0.75, 1.0 - PLATEAU])
    pos = np.append((np.arange(W)[:, None] + u[None, :]).ravel(), float(W))
    keys = np.empty((C, 6 * W + 1))
    keys[:, 0:6 * W:6] = sink[:, :W]
    keys[:, 1:6 * W:6] = sink[:, :W]
    keys[:, 2:6 * W:6] = d * k
    keys[:, 3:6 * W:6] = -d * nxt
    keys[:, 4:6 * W:6] = d * k
    keys[:, 5:6 * W:6] = sink[:, 1:]
    keys[:, 6 * W] = sink[:, W]
    return pos, keys


def knit_curves(pattern: str, wales: int, courses: int, w: float, h: float, r: float,
                samples_per_stitch: int = 16, tube: bool = False):
    if wales < 1 or courses < 1:
        raise ValueError(f"wales and courses must be >= 1, got {wales} x {courses}")
    if not (w > 0 and h > 0 and r > 0):
        raise ValueError("wale spacing, course spacing and yarn radius must be positive")
    s = int(samples_per_stitch)
    if s < 8:
        raise ValueError(f"samples per stitch must be >= 8 for the loop model, got {s}")
    if tube and wales < 3:
        raise ValueError("a tube needs at least 3 wales")
    k = stitch_types(pattern, wales, courses)
    d = DEPTH_FACTOR * r
    c = LOOP_HALF_HEIGHT * h
    n = wales * s + (0 if tube else 1)
    t = np.arange(n) / s                                    # stitch coordinate along the course
    pos, keys = _depth_keys(k, d, SINKER_CLEARANCE * r, tube)
    q0 = np.clip(np.searchsorted(pos, t, side="right") - 1, 0, len(pos) - 2)
    f = (t - pos[q0]) / (pos[q0 + 1] - pos[q0])
    blend = 0.5 * (1.0 - np.cos(np.pi * f))               # half-cosine between key depths
    z = keys[:, q0] + (keys[:, q0 + 1] - keys[:, q0]) * blend[None, :]
    x = w * (t + LEAN * np.sin(4.0 * np.pi * t)) - 0.5 * w * wales
    y = h * np.arange(courses)[:, None] - c * np.cos(2.0 * np.pi * t)[None, :] - 0.5 * h * (courses - 1)
    out = np.empty((courses, n, 3))
    if tube:
        R = wales * w / (2.0 * np.pi)
        theta = (x + 0.5 * w * wales) / R
        rad = R + z
        out[:, :, 0] = rad * np.cos(theta)[None, :]
        out[:, :, 1] = y
        out[:, :, 2] = rad * np.sin(theta)[None, :]
    else:
        out[:, :, 0] = x[None, :]
        out[:, :, 1] = y
        out[:, :, 2] = z
    return out, np.full(courses, bool(tube))

