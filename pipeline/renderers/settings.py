"""A method's numeric ``--set KEY=VALUE`` settings, read once the same way: the text as an integer or a number,
finite, within its bounds, or a one-line error naming ``--set KEY`` (exit code 2)."""
from __future__ import annotations

import math

from ..errors import LoomError


def number_setting(extra: dict, key: str, default, kind=float, lo=None, hi=None, above=None, what=None):
    """``--set key`` (``extra[key]``, a string) as ``kind`` (int or float), ``default`` when it is not given.
    Bounds: ``lo`` <= x <= ``hi`` (either may be None) and, with ``above``, x > ``above``; ``what`` says in the
    messages what the number counts."""
    v = extra.get(key)
    if v is None:
        return default
    noun = what or ("an integer" if kind is int else "a number")
    try:
        x = kind(v)
    except ValueError:
        raise LoomError(None, f"--set {key}", f"expected {noun}, got {v!r}") from None
    bounds = [f">= {lo:g}" if lo is not None else "", f"<= {hi:g}" if hi is not None else "",
              f"> {above:g}" if above is not None else ""]
    if (not math.isfinite(x) or (lo is not None and x < lo) or (hi is not None and x > hi)
            or (above is not None and not x > above)):
        raise LoomError(None, f"--set {key}", f"must be a finite number {' and '.join(b for b in bounds if b)} "
                        f"({noun}), got {v!r}")
    return x
