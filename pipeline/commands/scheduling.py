"""The ``--scheduler``, ``--workers`` and ``--threads-per-worker`` options of the stages that run chunk
tasks (render, realize, voxelize, precompute): where the tasks run (``pipeline.chunks``)."""
from __future__ import annotations

import typer

from ..chunks import SCHEDULER_HELP, THREADS_HELP, WORKERS_HELP

SCHEDULER = typer.Option(None, "--scheduler", metavar="<local | processes | tcp://HOST:PORT>", help=SCHEDULER_HELP)
WORKERS = typer.Option(None, "--workers", help=WORKERS_HELP)
THREADS_PER_WORKER = typer.Option(None, "--threads-per-worker", help=THREADS_HELP)
