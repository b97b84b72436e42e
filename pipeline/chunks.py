"""Chunk tasks: independent pieces of a stage (image tiles, yarns, blocks, cells).

A chunk task is a picklable callable (a module-level function plus arguments) that opens the
artifact being built at ``store_path`` and writes its own zarr chunks, nothing else. Tasks never
share a chunk, so they can run in any order, in any process: ``run_tasks`` runs them here with a
progress bar; a distributed scheduler (Dask's ``client.map``) can run the very same list.
Deterministic results follow from each task seeding its own random numbers from its chunk index.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import zarr

from .progress import progress


@dataclass(frozen=True)
class ChunkTask:
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)

    def __call__(self):
        return self.fn(*self.args, **self.kwargs)


def open_for_chunk(store_path, name: str):
    """Open one array of an artifact under construction for writing its chunks."""
    return zarr.open_array(str(store_path), path=name, mode="r+")


def run_tasks(tasks: Sequence[ChunkTask], description: str) -> list:
    results = []
    with progress(description, len(tasks)) as advance:
        for t in tasks:
            results.append(t())
            advance()
    return results
