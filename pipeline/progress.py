"""A rich progress bar for anything that takes longer than about a second.

Bars go to stderr and disappear when stderr is not a terminal unless LOOMLIGHT_PROGRESS=1.
"""
from __future__ import annotations

import os
import sys
from contextlib import contextmanager

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

_console = Console(stderr=True)


def _enabled() -> bool:
    flag = os.environ.get("LOOMLIGHT_PROGRESS")
    if flag is not None:
        return flag not in ("0", "", "false", "no")
    return sys.stderr.isatty()


@contextmanager
def progress(description: str, total: int):
    """Yield ``advance(n=1)``; draws a bar with elapsed and remaining time."""
    if not _enabled():
        yield lambda n=1: None
        return
    bar = Progress(
        TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
        TimeElapsedColumn(), TimeRemainingColumn(), console=_console, transient=False,
    )
    with bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)


def info(message: str) -> None:
    _console.print(message, highlight=False, soft_wrap=True)


def warn(message: str) -> None:
    _console.print(f"[yellow]warning:[/yellow] {message}", highlight=False, soft_wrap=True)
