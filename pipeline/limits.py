"""Accepted ranges of the numbers loomlight reads from files and the command line.

- NaN and inf are refused everywhere (TOML files: ``pipeline.toml_file``; curve files: their readers).
- Coordinates lie within +-``MAX_COORD`` scene units (curve control points, camera, light vectors):
  beyond, float32 positions have lost their digits and the segment grids, frames and tables overflow.
- Lengths (radii, spacings, scales) are finite, positive and at most ``MAX_LENGTH``.
- Light values (irradiance, radiance, power) are at most ``MAX_LIGHT``.
- Path depths (``max_depth``, ``rr_depth`` of every render and precompute) are at most ``MAX_PATH_DEPTH``:
  they cap work that Russian roulette ends long before, so past it a number is a typo, not a setting.
  ``FULL_TRANSPORT_DEPTH`` is the depth by which cloth's paths have carried all their light.
- Counts a stage works through (paths per cell, SG counts) are bounded by time where their memory does
  not grow with them: ``WorkEstimate`` refuses a run whose least time exceeds the time limit
  (``LOOMLIGHT_TIME_LIMIT`` hours, default 24), with the estimate in the message, as
  ``pipeline.memory.Estimate`` refuses one past the memory budget.

The schemas (``schemas/*.schema.json``) state the same limits; input beyond them is refused with
the limit in the message, never published.
"""
from __future__ import annotations

import math
import os

from .errors import LoomError

MAX_COORD = 1e6
MAX_LENGTH = 1e6
MAX_LIGHT = 1e9
MAX_PATH_DEPTH = 10_000
# The depth at which cloth's paths have carried their light: the default of what must hold the full transport
# (fit-bysdf's renders, the IIRTF's paths, the comparisons' references). Cloth keeps light through many fibres:
# fiberpath on the demo swatch keeps 0.60-0.68 of depth 1,024's light at depth 16, 0.82-0.87 at 32, 0.95-0.96 at
# 64, 1.000 at 256 (docs/evaluate.md); Russian roulette ends most paths long before, so it costs little.
FULL_TRANSPORT_DEPTH = 256


def check_positive(value, place: str, file=None, upper: float = MAX_LENGTH):
    """``value`` when it is finite, > 0 and <= ``upper``, else a LoomError naming ``place``."""
    if value is not None and not (math.isfinite(value) and 0 < value <= upper):
        limit = f"at most {upper:g}" if math.isfinite(upper) else "finite"
        raise LoomError(file, place, f"must be positive and {limit}, got {value}")
    return value


def check_depth(value: int, place: str, file=None) -> int:
    """``value`` when it is an integer from 1 to ``MAX_PATH_DEPTH``, else a LoomError naming ``place``."""
    if not 1 <= value <= MAX_PATH_DEPTH:
        raise LoomError(file, place, f"must be from 1 to {MAX_PATH_DEPTH:,} scattering events, got {value:,}")
    return value


def coordinate_problem(values) -> str | None:
    """Why a row of coordinates is refused (non-finite, or beyond +-MAX_COORD), None when accepted."""
    for v in values:
        if not math.isfinite(v):
            return f"non-finite coordinate {list(values)}"
        if abs(v) > MAX_COORD:
            return f"coordinate {v:g} is beyond +-{MAX_COORD:g} scene units"
    return None


def first_bad_row(points) -> int:
    """Index of the first row of an (n, 3) array with a non-finite or out-of-range coordinate, or -1."""
    import numpy as np

    pts = np.asarray(points, dtype=np.float64)
    bad = ~(np.abs(pts) <= MAX_COORD).all(axis=1)
    return int(np.argmax(bad)) if bad.any() else -1


# ------------------------------------------------------------------------------------------------ time
TIME_LIMIT_ENV = "LOOMLIGHT_TIME_LIMIT"   # hours
DEFAULT_TIME_LIMIT_H = 24.0


def time_limit() -> tuple[float, str]:
    """(seconds, where it comes from): $LOOMLIGHT_TIME_LIMIT hours, else ``DEFAULT_TIME_LIMIT_H``."""
    env = os.environ.get(TIME_LIMIT_ENV)
    if env:
        try:
            h = float(env)
        except ValueError:
            h = float("nan")
        if not (math.isfinite(h) and h > 0):
            raise LoomError(None, TIME_LIMIT_ENV, f"must be a positive number of hours, got {env!r}")
        return 3600.0 * h, f"{TIME_LIMIT_ENV}"
    return 3600.0 * DEFAULT_TIME_LIMIT_H, f"the default; {TIME_LIMIT_ENV} sets it, in hours"


def fmt_seconds(s: float) -> str:
    for unit, f in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if s >= f:
            return f"{s / f:.3g} {unit}"
    return f"{s:.3g} s"


class WorkEstimate:
    """The least wall time a stage can take, as named parts: ``add(label, count, per_thread_s, detail)``
    (``count`` units of work at ``per_thread_s`` units per second on one thread), spread over ``threads``.

    The bound from time for a count option whose memory does not grow with it (paths per cell, SG
    counts): the rates are faster than any measured, so a refused run could not have finished within
    the limit either. ``check`` raises the one-line refusal, with the estimate, before any work starts."""

    def __init__(self, what: str, threads: int):
        self.what = what
        self.threads = max(1, int(threads))
        self.parts: list[tuple[str, float, str]] = []

    def add(self, label: str, count: float, per_thread_s: float, detail: str = "") -> "WorkEstimate":
        self.parts.append((label, float(count) / (float(per_thread_s) * self.threads), detail))
        return self

    @property
    def seconds(self) -> float:
        return float(sum(s for _, s, _ in self.parts))

    def check(self, file=None, place: str | None = None, remedy: str = "lower it") -> None:
        limit, how = time_limit()
        if self.seconds > limit:
            parts = sorted(self.parts, key=lambda p: -p[1])[:2]
            text = "; ".join(f"{label} {fmt_seconds(s)}" + (f" ({d})" if d else "") for label, s, d in parts)
            raise LoomError(file, place, f"{self.what} would take at least an estimated {fmt_seconds(self.seconds)} "
                            f"on {self.threads} thread(s) ({text}), over the time limit of {limit / 3600:g} h "
                            f"({how}); nothing was started: {remedy}")


def largest_option(est, default: str) -> str:
    """The command-line option named in the detail of an estimate's largest part (``... (--sg-count)``), else
    ``default``: the place of a refusal by a ``WorkEstimate`` or a ``pipeline.memory.Estimate``."""
    import re

    parts = sorted(est.parts, key=lambda t: -t[1])
    m = re.search(r"\((--[a-z-]+)\)", parts[0][2]) if parts else None
    return m.group(1) if m else default
