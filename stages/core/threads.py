"""Loops over independent items on threads, without numba's parallel loops.

``for_chunks(kernel, n, *args)`` calls ``kernel(*args, start, stop)`` for contiguous chunks [start, stop) of
range(n), on numba's thread count of Python threads; ``kernel`` is a ``chunk_kernel`` (``nogil``), so the chunks
run at once. It replaces ``@njit(parallel=True)`` + ``prange`` where every item writes only its own
outputs: the same floats whatever the thread count or order, and far less to compile (numba's parallel
loops turn each ``prange`` body into a gufunc of its own and compile it with the kernel: most of
``realize_fill_window``'s compile time on a cold cache, ``make compile-report``). The tile loop of the renderers
(``stages.render.tiles``) splits its work the same way.

A chunk's kernel is declared ``@chunk_kernel``: ``nogil`` and numba's ``numpy`` error model, as numba compiles
a ``prange`` body (a division by zero gives inf or nan rather than raising; without it the IIRTF's cells ran
10-15 % slower, the zero checks in the loop).

``CHUNKS_PER_THREAD`` chunks per thread balance items of unequal cost (yarns of different lengths) at a
dispatch of about a microsecond per argument per chunk; loops whose items range from nothing to a whole
cell's paths (the IIRTF's cells, the BTF's texels) ask for more (``chunks_per_thread``).
"""
import threading

import numpy as np
from numba import njit

CHUNKS_PER_THREAD = 4

chunk_kernel = njit(cache=True, nogil=True, error_model="numpy")


def chunk_bounds(n: int, chunks: int) -> np.ndarray:
    """(chunks + 1,) int64 bounds splitting range(n) into ``chunks`` contiguous runs of near-equal length."""
    chunks = max(1, min(int(chunks), int(n)))
    return (np.arange(chunks + 1, dtype=np.int64) * int(n)) // chunks


def for_chunks(kernel, n: int, *args, threads: int | None = None, chunks_per_thread: int = CHUNKS_PER_THREAD) -> None:
    """``kernel(*args, start, stop)`` over contiguous chunks of range(n) on ``threads`` threads (default:
    numba's thread count), ``chunks_per_thread`` chunks each. Exceptions raised by a chunk are raised here."""
    import numba

    n = int(n)
    if n <= 0:
        return
    t = max(1, int(threads or numba.get_num_threads()))
    b = chunk_bounds(n, 1 if t == 1 else t * max(1, int(chunks_per_thread)))
    if t == 1 or len(b) == 2:
        kernel(*args, b[0], b[-1])
        return
    list(_pool(t).map(lambda i: kernel(*args, b[i], b[i + 1]), range(len(b) - 1)))


_pools: dict = {}
_pools_lock = threading.Lock()


def _pool(t: int):
    """A thread pool of ``t`` workers kept for the process (starting one per call cost ~1 ms, which the
    procedural lookups' many small calls paid). Chunk kernels never call ``for_chunks`` themselves, so
    a task never waits on the pool it runs in."""
    with _pools_lock:
        ex = _pools.get(t)
        if ex is None:
            from concurrent.futures import ThreadPoolExecutor

            ex = _pools[t] = ThreadPoolExecutor(max_workers=t, thread_name_prefix="loomlight-chunks")
        return ex
