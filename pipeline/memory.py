"""Memory budgets: a stage estimates its peak memory from its inputs before it allocates anything
large, and refuses to start past its budget, with the estimate in the message, instead of being
killed by the OOM killer (or swapping for minutes) half-way.

The budget is ``--budget MIB`` where a command has it, else ``LOOMLIGHT_MEMORY_BUDGET`` (MiB) from
the environment, else ``DEFAULT_FRACTION`` of the memory available now (``MemAvailable`` of
/proc/meminfo, bounded by the cgroup's limit). An ``Estimate`` is a sum of named parts, each the
bytes a piece of the stage holds at its peak (counted from the sizes the inputs imply: yarns,
plies, fibres, bins, hairs, vertices, voxels, pixels), written by the stage's runner;
``Estimate.check`` raises the one-line refusal naming the largest parts.

Only the standard library here: command modules import it for ``--budget``'s help.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

from .errors import LoomError

DEFAULT_FRACTION = 0.75
KERNEL_BYTES = 128 << 20   # numba kernels loaded from the cache (compiling them the first time takes more)
BUDGET_ENV = "LOOMLIGHT_MEMORY_BUDGET"
BUDGET_HELP = ("Refuse to start when the stage's estimated peak memory exceeds this many MiB "
               f"(default: {BUDGET_ENV}, else {int(DEFAULT_FRACTION * 100)} % of the memory available).")


class Budget(NamedTuple):
    nbytes: int
    how: str          # where it comes from, for the refusal message


def _proc_kib(path: str, key: str) -> int | None:
    """The ``key:`` line of a /proc file given in kB, in bytes; None where it cannot be read."""
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def peak_rss_bytes() -> int:
    """This process's peak resident memory: ``VmHWM`` of /proc/self/status, the high-water mark of this
    program's own address space. ``getrusage``'s ``ru_maxrss`` (the fallback where /proc is missing) is
    not that on Linux: a child forked from a large process and exec'd keeps the parent's peak as its
    own, so a render started by another loomlight process would report its parent's memory."""
    hwm = _proc_kib("/proc/self/status", "VmHWM")
    if hwm is not None:
        return hwm
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)


def _meminfo_available() -> int | None:
    return _proc_kib("/proc/meminfo", "MemAvailable")


def _cgroup_room() -> int | None:
    """Room left under this process's cgroup memory limit (v2, then v1); None without a limit."""
    for limit_f, usage_f in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                             ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                              "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            limit = Path(limit_f).read_text().strip()
            if limit == "max" or int(limit) >= 1 << 60:
                return None
            return max(0, int(limit) - int(Path(usage_f).read_text().strip()))
        except (OSError, ValueError):
            continue
    return None


def available_bytes() -> int:
    """Memory this process can still take: MemAvailable, bounded by the cgroup's limit."""
    found = [v for v in (_meminfo_available(), _cgroup_room()) if v is not None]
    if not found:
        try:
            found = [os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")]
        except (OSError, ValueError):
            found = [1 << 30]
    return int(min(found))


def budget(mib: float | None = None) -> Budget:
    """The budget of a stage: ``--budget`` (MiB), else $LOOMLIGHT_MEMORY_BUDGET (MiB), else a fraction of
    the memory available."""
    if mib is not None:
        return Budget(_mib(mib, None, "--budget"), "--budget")
    env = os.environ.get(BUDGET_ENV)
    if env:
        return Budget(_mib(env, None, BUDGET_ENV), BUDGET_ENV)
    avail = available_bytes()
    return Budget(int(DEFAULT_FRACTION * avail), f"{int(DEFAULT_FRACTION * 100)} % of the {fmt_bytes(avail)} available")


def _mib(value, file, place) -> int:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise LoomError(file, place, f"memory budget must be a number of MiB, got {value!r}") from None
    if not (v > 0 and v < float("inf")):
        raise LoomError(file, place, f"memory budget must be a positive number of MiB, got {value}")
    return int(v * 2**20)


def fmt_bytes(n: float) -> str:
    for unit, f in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= f:
            return f"{n / f:.1f} {unit}"
    return f"{int(n)} B"


class Estimate:
    """The peak memory of a stage as named parts: ``add(label, nbytes, detail)``; ``check(budget)``."""

    def __init__(self, what: str, kernels: bool = True):
        self.what = what
        self.parts: list[tuple[str, float, str]] = []
        if kernels:
            self.add("numba kernels", KERNEL_BYTES)

    def add(self, label: str, nbytes: float, detail: str = "") -> "Estimate":
        self.parts.append((label, max(0.0, float(nbytes)), detail))
        return self

    def extend(self, other: "Estimate") -> "Estimate":
        have = {label for label, _, _ in self.parts}
        self.parts.extend(p for p in other.parts if not (p[0] == "numba kernels" and p[0] in have))
        return self

    @property
    def total(self) -> float:
        return float(sum(b for _, b, _ in self.parts))

    def describe(self, top: int = 3) -> str:
        parts = sorted((p for p in self.parts if p[1] > 0), key=lambda p: -p[1])
        text = [f"{label} {fmt_bytes(b)}" + (f" ({detail})" if detail else "") for label, b, detail in parts[:top]]
        return "; ".join(text)

    def check(self, limit: Budget, file=None, place: str | None = None,
              remedy: str = "raise --budget or make the input smaller") -> None:
        """Refuse (LoomError, exit code 2) when the estimate exceeds the budget; ``remedy`` ends the line."""
        if self.total > limit.nbytes:
            raise LoomError(file, place, f"{self.what} needs an estimated {fmt_bytes(self.total)} of memory "
                            f"({self.describe()}), over the budget of {fmt_bytes(limit.nbytes)} ({limit.how}); "
                            f"nothing was started: {remedy}")
