"""Progress on stderr for anything that takes longer than a few seconds: bars, spinners, compilation.

``progress(description, total)`` yields ``advance(n=1)`` for work counted in steps (tiles, chunk tasks);
``status(description)`` is a spinner for work that cannot be counted (a whole stage, a compilation);
``info`` and ``warn`` print a message. What is shown depends on where stderr goes (``mode``):

``live``   (stderr is a terminal, or ``LOOMLIGHT_PROGRESS=1``): rich bars and spinners in one live display,
           so a stage's spinner, its bars and a compilation notice show together, one line each.
``plain``  (stderr is a log, a pipe, a file; or ``LOOMLIGHT_PROGRESS=plain``): plain lines, none for
           work shorter than ``LOOMLIGHT_PROGRESS_INTERVAL`` seconds (default 30), then one line that
           often while it runs (count, elapsed and remaining time) and one when it ends. Nothing runs for
           minutes without a line (a compilation says so at once: ``pipeline.compilation``).
``off``    (``LOOMLIGHT_PROGRESS=0``; the test suite sets it): no bars, spinners or lines; messages stay.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager

from rich.console import Console
from rich.progress import BarColumn, Progress, ProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.text import Text

_console = Console(stderr=True)
PROGRESS_ENV = "LOOMLIGHT_PROGRESS"
INTERVAL_ENV = "LOOMLIGHT_PROGRESS_INTERVAL"
DEFAULT_INTERVAL_S = 30.0


def mode() -> str:
    """``live``, ``plain`` or ``off`` (module doc)."""
    flag = os.environ.get(PROGRESS_ENV)
    if flag is not None:
        f = flag.strip().lower()
        if f in ("0", "", "false", "no", "off"):
            return "off"
        return "plain" if f == "plain" else "live"
    try:
        return "live" if sys.stderr.isatty() else "plain"
    except (AttributeError, ValueError):  # a closed or replaced stderr
        return "plain"


def interval_s() -> float:
    """Seconds between two plain lines of the same work (``LOOMLIGHT_PROGRESS_INTERVAL``, at least 1)."""
    try:
        return max(1.0, float(os.environ.get(INTERVAL_ENV, DEFAULT_INTERVAL_S)))
    except ValueError:
        return DEFAULT_INTERVAL_S


def clock(seconds: float) -> str:
    """A duration for people: ``8.2 s``, ``3 min 05 s``, ``1 h 02 min``."""
    s = max(0.0, float(seconds))
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


class _Count(ProgressColumn):
    """``12/40`` for counted work, nothing for a spinner."""

    def render(self, task):
        return Text("" if task.total is None else f"{int(task.completed)}/{int(task.total)}", style="progress.download")


class _Remaining(TimeRemainingColumn):
    def render(self, task):
        return Text("") if task.total is None else super().render(task)


class _Work:
    """One bar or spinner: what plain lines are made of."""

    def __init__(self, description: str, total: int | None, done: str | None = None):
        self.description = description
        self.total = total
        self.completed = 0
        self.start = self.last = time.perf_counter()
        self.printed = False
        self.done = done          # the line printed when it ends (plain: only if it printed before; live: always)
        self.rich_id = None

    def line(self, now: float) -> str:
        el = now - self.start
        if self.total is None:
            return f"{self.description}: {clock(el)} elapsed"
        frac = self.completed / self.total if self.total else 1.0
        left = f", ~{clock(el * (1 - frac) / frac)} left" if 0 < frac < 1 else ""
        return f"{self.description}: {self.completed}/{self.total} ({100 * frac:.0f} %), {clock(el)} elapsed{left}"


_lock = threading.RLock()
_works: list[_Work] = []
_live: Progress | None = None
_beat: threading.Thread | None = None


def _print(text: str) -> None:
    _console.print(text, highlight=False, markup=False, soft_wrap=True)


def _heartbeat() -> None:
    """Plain mode: every ``interval_s``, a line for the innermost work (the one started last: a bar inside
    a stage's spinner, a compilation inside a bar); the works around it are running too."""
    global _beat
    while True:
        time.sleep(min(1.0, interval_s() / 4))
        with _lock:
            if not _works:
                _beat = None
                return
            now = time.perf_counter()
            w = _works[-1]
            if now - max(v.last for v in _works) >= interval_s():
                _print(w.line(now))
                w.last, w.printed = now, True


def begin(description: str, total: int | None = None, announce: str | None = None, done: str | None = None):
    """Start a bar (``total`` steps) or a spinner (``total`` None); returns its handle, or None when
    progress is off. ``announce``: a line printed now (plain and live), e.g. what starts compiling;
    ``done``: the line that ends it (plain mode: only after an announcement or a progress line)."""
    global _live, _beat
    m = mode()
    if m == "off":
        return None
    w = _Work(description, total, done)
    with _lock:
        if m == "live":
            if _live is None:
                _live = Progress(TextColumn("[bold]{task.description}"), BarColumn(), _Count(), TimeElapsedColumn(),
                                 _Remaining(), console=_console, transient=False)
                _live.start()
            if announce:
                _live.console.print(announce, highlight=False, markup=False, soft_wrap=True)
            w.rich_id = _live.add_task(description, total=total)
        else:
            if announce:
                _print(announce)
                w.printed = True
            if _beat is None:
                _beat = threading.Thread(target=_heartbeat, name="loomlight-progress", daemon=True)
                _beat.start()
        _works.append(w)
    return w


def advance(w, n: int = 1) -> None:
    if w is None:
        return
    with _lock:
        w.completed += n
        if w.rich_id is not None and _live is not None:
            _live.advance(w.rich_id, n)


def relabel(w, description: str) -> None:
    """Change what a bar or spinner says (a run of named steps: ``warmup``)."""
    if w is None:
        return
    with _lock:
        w.description = description
        if w.rich_id is not None and _live is not None:
            _live.update(w.rich_id, description=description)


def end(w, keep: bool = True) -> None:
    """Finish a bar or spinner; ``keep`` a finished bar on a terminal (spinners never stay)."""
    global _live
    if w is None:
        return
    with _lock:
        if w in _works:
            _works.remove(w)
        if w.rich_id is not None and _live is not None:
            if not keep or w.total is None:
                _live.remove_task(w.rich_id)
            if w.done:
                _live.console.print(w.done, highlight=False, markup=False, soft_wrap=True)
            if not _works:
                _live.stop()
                _live = None
        elif w.printed:
            now = time.perf_counter()
            _print(w.done or (f"{w.description}: done in {clock(now - w.start)}" if w.total is None else
                              f"{w.description}: {w.completed}/{w.total} done in {clock(now - w.start)}"))


@contextmanager
def progress(description: str, total: int):
    """Yield ``advance(n=1)``; a bar with elapsed and remaining time (plain lines off a terminal)."""
    w = begin(description, total)
    try:
        yield lambda n=1: advance(w, n)
    finally:
        end(w)


@contextmanager
def status(description: str):
    """A spinner with the elapsed time while the block runs (plain lines off a terminal)."""
    w = begin(description, None)
    try:
        yield
    finally:
        end(w)


def info(message: str) -> None:
    _console.print(message, highlight=False, soft_wrap=True)


def warn(message: str) -> None:
    _console.print(f"[yellow]warning:[/yellow] {message}", highlight=False, soft_wrap=True)
