"""Weave drafts as interlacement matrices.

An interlacement matrix ``over`` has shape (ends, picks), boolean: ``over[e, p]`` is True where
warp end ``e`` passes over weft pick ``p`` (the warp is on top, seen from +z). A row is the
path of one warp end across the picks; a run of True along a row is a warp float.

Drafts (repeat tiled over the requested size, end 0 / pick 0 at the origin of the repeat):
- ``plain(ends, picks)``: checkerboard, over where (e + p) is even.
- ``twill(n, m, ends, picks)``: period n + m; warp end e is over picks e .. e+n-1 (mod n+m),
  so every warp floats over n picks and under m, and the float moves one pick per end (the
  twill diagonal).
- ``satin(n, ends, picks, step=None)``: warp-faced n-end satin; warp end e goes under only pick
  (step * e mod n), so every warp floats over n - 1 picks and every pick is bound once per
  repeat. The step (move number) must satisfy 1 < step < n - 1 and gcd(step, n) = 1, which is
  what keeps binding points from touching; n = 4 and n = 6 have none (use 5, 7, 8, ...).
- ``basket(n, ends, picks)``: plain weave of groups of n ends and n picks (warp floats over n).

From a loom description (``interlacement_from_draft``): boolean matrices threading (ends,
shafts), tie-up (treadles, shafts) + treadling (picks, treadles), or a lift plan (picks,
shafts). The shafts lifted at pick p are the lift-plan row, or the union of the tie-ups of the
treadles pressed; warp end e is over pick p when one of its shafts is lifted (rising shed). In a
sinking shed the tie-up names the shafts that sink, so the matrix is inverted.

Pure numpy; invalid parameters raise ValueError (the pipeline turns it into a LoomError).
"""
from __future__ import annotations

from math import gcd

import numpy as np


def _grid(ends: int, picks: int):
    if ends < 1 or picks < 1:
        raise ValueError(f"ends and picks must be >= 1, got {ends} x {picks}")
    e = np.arange(ends)[:, None]
    p = np.arange(picks)[None, :]
    return e, p


def plain(ends: int, picks: int) -> np.ndarray:
    e, p = _grid(ends, picks)
    return (e + p) % 2 == 0


def twill(n: int, m: int, ends: int, picks: int) -> np.ndarray:
    if n < 1 or m < 1:
        raise ValueError(f"twill {n}/{m}: n and m must be >= 1")
    e, p = _grid(ends, picks)
    return (p - e) % (n + m) < n


def satin_steps(n: int) -> list[int]:
    """Valid move numbers of an n-end satin: 1 < s < n-1, gcd(s, n) = 1."""
    return [s for s in range(2, n - 1) if gcd(s, n) == 1]


def satin(n: int, ends: int, picks: int, step: int | None = None) -> np.ndarray:
    steps = satin_steps(n)
    if not steps:
        raise ValueError(f"satin {n}: no valid step (move number) exists for n = {n}; use n = 5, 7, 8 or more")
    if step is None:
        step = steps[0]
    elif step not in steps:
        raise ValueError(f"satin {n}: step {step} is not valid, choose one of {steps}")
    e, p = _grid(ends, picks)
    return p % n != (step * e) % n


def basket(n: int, ends: int, picks: int) -> np.ndarray:
    if n < 1:
        raise ValueError(f"basket {n}: n must be >= 1")
    e, p = _grid(ends, picks)
    return (e // n + p // n) % 2 == 0


def interlacement_from_draft(threading: np.ndarray, tieup: np.ndarray | None = None,
                             treadling: np.ndarray | None = None, liftplan: np.ndarray | None = None,
                             rising: bool = True) -> np.ndarray:
    """(ends, shafts) threading + ((treadles, shafts) tie-up and (picks, treadles) treadling, or a
    (picks, shafts) lift plan) -> (ends, picks) interlacement."""
    threading = np.asarray(threading, dtype=bool)
    if liftplan is not None:
        lifted = np.asarray(liftplan, dtype=bool)
    else:
        if tieup is None or treadling is None:
            raise ValueError("a draft needs a lift plan, or a tie-up and a treadling")
        lifted = (np.asarray(treadling, dtype=np.int64) @ np.asarray(tieup, dtype=np.int64)) > 0
    if lifted.shape[1] != threading.shape[1]:
        raise ValueError(f"shaft counts disagree: threading {threading.shape[1]}, lifts {lifted.shape[1]}")
    over = (threading.astype(np.int64) @ lifted.T.astype(np.int64)) > 0
    return over if rising else ~over


def float_lengths(row: np.ndarray, value: bool = True) -> list[int]:
    """Lengths of the cyclic runs of ``value`` along a periodic row (a whole-row run counts once)."""
    row = np.asarray(row, dtype=bool)
    if (row == value).all():
        return [len(row)]
    if not (row == value).any():
        return []
    k = int(np.argmin(row == value))  # start just after a run boundary
    r = np.roll(row, -k)
    runs, cnt = [], 0
    for v in r:
        if v == value:
            cnt += 1
        elif cnt:
            runs.append(cnt)
            cnt = 0
    if cnt:
        runs.append(cnt)
    return runs


def tile(over: np.ndarray, repeat_ends: int, repeat_picks: int) -> np.ndarray:
    return np.tile(over, (repeat_ends, repeat_picks))
