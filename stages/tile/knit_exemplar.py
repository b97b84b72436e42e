"""Knitted exemplars: one periodic repeat of a weft-knitted fabric realized to explicit fibres.

The knitted counterpart of ``stages.tile.exemplar`` (whose periodic fibres, wrapped pieces and blocks
it shares): ``wales`` x ``courses`` stitches of a knit ``pattern`` (stockinette, garter or rib1x1: the
loop model of ``stages.core.curves.knit``, the ingest knit generator's) with wale spacing ``w`` and
course spacing ``h``. Exemplar space: x in [0, W = wales w), y in [0, H = courses h), z up. Course i
runs along +x about y = (i + 1/2) h; stitch j lies between its sinkers at x = j w and x = (j + 1) w,
its head at x = (j + 1/2) w, y = (i + 1/2) h + c and its necks at y = (i + 1/2) h - c with c = 1.1 h:
the loops of course i reach into courses i - 1 and i + 1 (the head is pulled through by course i + 1,
the necks pass through the head of course i - 1). Each course is one yarn (group knit); a weft knit
has no warp.

Stitch repeat
    A pattern repeats every (``natural_repeat``) 1 x 1 stitches (stockinette), 1 wale x 2 courses
    (garter: knit and purl courses alternate), 2 wales x 1 course (rib1x1: knit and purl wales
    alternate); ``wales`` and ``courses`` must be multiples of it.

Periodic course centrelines
    ``knit_centreline``: the loop model's curves of 3 x 3 repeats (``knit_curves(pattern, 3 wales,
    3 courses, ...)``, ``DENSE_STITCH`` samples per stitch), of which the middle repeat's courses, over
    their middle repeat of stitches, are taken and shifted by (W/2, H/2, 0). There every sinker, and
    the course below and above, is that of the endless fabric, so the course is exactly periodic along
    its length: c(s + L) = c(s) + (W, 0, 0), L the arc length of one repeat (chords of the dense
    samples). Frame: n is the component of +z normal to the tangent, b = t x n, as in the woven
    exemplar (periodic; a knitted course is not planar, so it is not the rotation-minimising frame);
    the tangent keeps a horizontal part of at least 0.65 of its length at the generator's default
    radius (x' > 0 wherever y' = 0, the loop model's doc), and ``realize_knit_exemplar`` refuses a
    radius at which it would fall below ``MIN_HORIZONTAL``.

Periodic fibres
    As in the woven exemplar (``stages.tile.exemplar.periodic_yarn_fibres``): pitches snapped to whole
    fractions of L, regular fibres of the procedural yarn model placed by seed 000 Eq. 7, the last point
    of every fibre its first point moved by (W, 0, 0). The loop depth is d = 3 r (garter sinkers
    5 r), so a knit's fibres span about 8 r in z (10 r for garter), against about 4 r for a woven
    cloth at crimp 1.

Blocks and wrapping
    ``wrap_pieces`` and ``segment_blocks`` of ``stages.tile.exemplar`` apply unchanged: the copies
    shifted by (a W, b H), a, b in {-1, 0, 1}, hold every capsule that reaches the exemplar box as long
    as every fibre surface lies within x in (-W, 2W), y in (-H, 2H) (a copy two periods away then
    misses the box). A course reaches c + r_yarn beyond its mean line, so this holds whenever
    h / 2 + H > c + r_yarn; ``realize_knit_exemplar`` checks it on the realized fibres.

Pure numpy / numba; invalid parameters raise ValueError (the pipeline turns it into a LoomError).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from stages.core.curves.knit import PATTERNS, knit_curves, stitch_types
from stages.core.rng import hash_u64

from .exemplar import centreline_frames, periodic_yarn_fibres

DENSE_STITCH = 256      # centreline samples per stitch (chord sagitta ~ 1e-4 w at the loop's head)
MIN_HORIZONTAL = 0.1    # the least horizontal part of the unit tangent the +z frame is built from
KNIT_GROUP = 2          # yarn group of a course (0 warp, 1 weft, 2 knit, 3 other)
KNIT_TYPE_SALT = 3      # type key of the fibre sampling (woven: 1 warp, 2 weft)


class KnitCentreline(NamedTuple):
    s: np.ndarray       # (M,) arc length of the dense samples, 0 at the repeat's start (x = 0)
    points: np.ndarray  # (M, 3) dense samples over the 3 repeats of stitches, exemplar space
    L: float            # arc length of one repeat of wales stitches


def natural_repeat(pattern: str):
    """(wales, courses) of one repeat of the pattern."""
    if pattern not in PATTERNS:
        raise ValueError(f"knit pattern {pattern!r}: expected one of {', '.join(PATTERNS)}")
    return {"stockinette": (1, 1), "garter": (1, 2), "rib1x1": (2, 1)}[pattern]


def check_repeat(pattern: str, wales: int, courses: int) -> None:
    """ValueError unless wales x courses is a whole number of the pattern's repeats."""
    nw, nc = natural_repeat(pattern)
    if wales < 1 or courses < 1:
        raise ValueError(f"wales and courses must be >= 1, got {wales} x {courses}")
    if wales % nw or courses % nc:
        raise ValueError(f"{pattern} repeats every {nw} wale(s) x {nc} course(s): {wales} wales x {courses} "
                         f"courses is not a whole number of repeats")


def knit_centreline(pattern: str, wales: int, courses: int, w: float, h: float, r: float,
                    course: int) -> KnitCentreline:
    """Dense samples of course ``course`` of the exemplar, periodic over its middle repeat (module doc)."""
    W, H = wales * w, courses * h
    curves, _ = knit_curves(pattern, 3 * wales, 3 * courses, w, h, r, DENSE_STITCH)
    pts = curves[courses + course] + np.array([0.5 * W, 0.5 * H, 0.0])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    m0 = wales * DENSE_STITCH        # the sample at t = wales: the sinker at x = 0
    return KnitCentreline(s - s[m0], pts, float(s[2 * m0] - s[m0]))


def realize_knit_exemplar(pattern, wales, courses, w, h, tp, r, seed, segment_length):
    """Explicit periodic fibres of one knitted repeat.

    Returns dict (the layout of ``stages.tile.exemplar.realize_exemplar``): points (M, 3), radius (M,),
    offsets (F+1,), fiber_yarn (F,) (the course), yarn_group (courses,) all 2 (knit), period (W, H),
    stitches (courses, wales) +1 knit / -1 purl."""
    check_repeat(pattern, wales, courses)
    if not (w > 0 and h > 0 and r > 0):
        raise ValueError("wale spacing, course spacing and yarn radius must be positive")
    W, H = wales * w, courses * h
    pts, rads, counts, fy = [], [], [], []
    tkey = int(hash_u64(seed, KNIT_TYPE_SALT, 7) >> np.uint64(1))
    for i in range(courses):
        c = knit_centreline(pattern, wales, courses, w, h, r, i)
        _, t, _, _ = centreline_frames(c.s, c.points, c.s[wales * DENSE_STITCH: 2 * wales * DENSE_STITCH + 1])
        horizontal = float(np.linalg.norm(t[:, :2], axis=1).min())
        if horizontal < MIN_HORIZONTAL:
            raise ValueError(f"yarn radius {r:g}: the course's tangent turns within {horizontal:.3g} of the z axis "
                             f"(loop depth 3 r against wale spacing {w:g}); the +z frame needs a smaller radius")
        ykey = int(hash_u64(seed, i, 11) >> np.uint64(1))
        yf = periodic_yarn_fibres(c.s, c.points, c.L, tp, tkey, ykey, segment_length)
        pts.append(yf.points)
        rads.append(yf.radius)
        counts += [yf.n_points] * yf.n_fibres
        fy += [i] * yf.n_fibres
    points, radius = np.concatenate(pts), np.concatenate(rads)
    lo = (points[:, :2] - radius[:, None]).min(axis=0)
    hi = (points[:, :2] + radius[:, None]).max(axis=0)
    if lo[0] <= -W or hi[0] >= 2 * W or lo[1] <= -H or hi[1] >= 2 * H:
        raise ValueError(f"the fibres span x in [{lo[0]:.4g}, {hi[0]:.4g}], y in [{lo[1]:.4g}, {hi[1]:.4g}]: more "
                         f"than one period ({W:g} x {H:g}) beyond the exemplar, which its 3 x 3 wrapped copies "
                         f"do not cover; use more courses per repeat or a smaller yarn radius")
    return {"points": points, "radius": radius,
            "offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            "fiber_yarn": np.asarray(fy, np.int32), "yarn_group": np.full(courses, KNIT_GROUP, np.int8),
            "period": (W, H), "stitches": stitch_types(pattern, wales, courses)}
