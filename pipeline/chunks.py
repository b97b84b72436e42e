"""Chunk tasks: independent pieces of a stage (image tiles, fibre blocks, voxel slabs, segments, cells).

A chunk task (``ChunkTask``) is a picklable callable (a module-level function plus arguments) that
opens the artifact being built at ``store_path`` and writes its own zarr chunks, nothing else, and
returns a small summary (timings, sums, bounds). Tasks never share a chunk, so they can run in any
order, in any process, any number of times: the bytes written depend only on the task's arguments
(each task seeds its random numbers from its chunk index).

Where they run -- the **scheduler** (``--scheduler`` of render, realize, voxelize and precompute; the
scene's ``render.scheduler``; the ``LOOMLIGHT_SCHEDULER`` environment variable; in that order):

``local`` (default)
    in this process, one task after the other, each on numba's threads. Dask is not imported.
``processes``
    a ``dask.distributed`` LocalCluster started and stopped by the command: ``--workers`` worker
    processes (default 2, ``LOOMLIGHT_WORKERS``) of ``--threads-per-worker`` numba threads each
    (default 1, ``LOOMLIGHT_THREADS_PER_WORKER``). Bounded before any process starts
    (``check_local_cluster``): the workers by the memory budget (``WORKER_BYTES`` each at least), a
    worker's threads by this machine's CPUs.
``tcp://HOST:PORT``
    a running Dask scheduler (``dask scheduler``) and its workers (``dask worker tcp://HOST:PORT``),
    which must see loomlight's code, the inputs and the output's directory at the same paths.

``session(spec)`` opens the scheduler once per command (a cluster is started, or the address is
connected, and the Dask dashboard's address is printed); ``run_tasks`` maps the tasks onto it,
draws the progress bar from task completions and returns the results in task order. A worker that
dies has its tasks rerun elsewhere (Dask's own retries): the artifact is the same bytes. A scheduler
that cannot be reached or is lost mid-run is a ``LoomError`` naming the address (exit 2): a refused
connection at once, silence after ``LOOMLIGHT_CONNECT_TIMEOUT`` seconds (default 10); the
artifact under construction is discarded by its writer, and the previous one stays.

``worker_cache(key, build)`` keeps what a task needs and its process already built (a BVH, the
procedural tables, an integrator) for the next task of the same command: a worker builds it once,
not once per task. It holds the most recent few entries; ``session`` clears it when the command ends.
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from .errors import LoomError
from .progress import info, progress

SCHEDULER_ENV = "LOOMLIGHT_SCHEDULER"
WORKERS_ENV = "LOOMLIGHT_WORKERS"
THREADS_ENV = "LOOMLIGHT_THREADS_PER_WORKER"
SCHEDULER_HELP = ("Where chunk tasks run: local (this process, default), processes (a Dask LocalCluster of "
                  "--workers processes, started and stopped here) or tcp://HOST:PORT (a running Dask scheduler). "
                  f"Default: the scene's render.scheduler, else ${SCHEDULER_ENV}, else local. Same bytes either way.")
WORKERS_HELP = f"--scheduler processes: worker processes (default ${WORKERS_ENV}, else 2)."
THREADS_HELP = f"--scheduler processes: numba threads per worker (default ${THREADS_ENV}, else 1)."
CONNECT_TIMEOUT_ENV = "LOOMLIGHT_CONNECT_TIMEOUT"   # seconds to reach a tcp:// scheduler (default 10)
WORKER_BYTES = 100 << 20   # the least a LocalCluster worker takes: Python with Dask, numpy and numba (~113 MiB)


@dataclass(frozen=True)
class ChunkTask:
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)

    def __call__(self):
        return self.fn(*self.args, **self.kwargs)


@dataclass(frozen=True)
class Scheduler:
    """Where chunk tasks run (module doc): ``kind`` local, processes or address."""
    kind: str = "local"
    address: str | None = None
    workers: int = 2
    threads_per_worker: int = 1

    @property
    def distributed(self) -> bool:
        return self.kind != "local"

    def describe(self) -> str:
        if self.kind == "processes":
            return f"a Dask LocalCluster of {self.workers} workers x {self.threads_per_worker} threads"
        return "the Dask scheduler at " + str(self.address) if self.kind == "address" else "this process"


def _positive_int(value, place, file=None) -> int:
    text = str(value).strip()
    if not text.isdigit() or int(text) < 1:
        raise LoomError(file, place, f"must be a positive integer, got {value!r}")
    return int(text)


def check_local_cluster(workers: int, threads: int, workers_place: str, threads_place: str) -> None:
    """Bounds of a LocalCluster on this machine, refused before a process starts: its worker processes by
    memory (each one at least ``WORKER_BYTES``, against the memory budget: ``pipeline.memory.budget``), a
    worker's numba threads by this machine's CPUs (more only wait for each other)."""
    from .memory import Estimate, budget

    Estimate("a Dask LocalCluster", kernels=False).add(
        "worker processes", float(workers) * WORKER_BYTES,
        f"{workers:,} workers x at least {WORKER_BYTES >> 20} MiB each (a Python process with Dask and numba)").check(
        budget(), None, workers_place, "lower it")
    cpus = os.cpu_count() or 1
    if threads > cpus:
        raise LoomError(None, threads_place, f"{threads:,} threads per worker is more than this machine's {cpus} "
                        "CPUs (more only wait for each other); lower it")


def parse_scheduler(value: str, place: str = "--scheduler", file=None, workers=None, threads=None) -> Scheduler:
    """A ``Scheduler`` from its name: ``local``, ``processes`` or ``tcp://HOST:PORT``."""
    v = str(value).strip()
    w = _positive_int(workers if workers is not None else os.environ.get(WORKERS_ENV, 2),
                      "--workers" if workers is not None else WORKERS_ENV)
    t = _positive_int(threads if threads is not None else os.environ.get(THREADS_ENV, 1),
                      "--threads-per-worker" if threads is not None else THREADS_ENV)
    if v == "processes":
        check_local_cluster(w, t, "--workers" if workers is not None else WORKERS_ENV,
                            "--threads-per-worker" if threads is not None else THREADS_ENV)
    if v in ("local", "processes"):
        return Scheduler(v, None, w, t)
    if v.startswith("tcp://"):
        host, _, port = v[len("tcp://"):].rpartition(":")
        if host and port.isdigit() and 0 < int(port) < 65536:
            return Scheduler("address", v, w, t)
        raise LoomError(file, place, f"expected tcp://HOST:PORT, got {value!r}")
    raise LoomError(file, place, f"unknown scheduler {value!r} (known: local, processes, tcp://HOST:PORT)")


def resolve_scheduler(cli: str | None = None, scene=None, workers=None, threads=None) -> Scheduler:
    """The scheduler of a command: ``--scheduler``, else the scene's ``render.scheduler``, else
    ``$LOOMLIGHT_SCHEDULER``, else local."""
    if cli is not None:
        return parse_scheduler(cli, "--scheduler", None, workers, threads)
    value = (scene.render.get("scheduler") if scene is not None else None)
    if value is not None:
        return parse_scheduler(value, "render.scheduler", scene.path, workers, threads)
    env = os.environ.get(SCHEDULER_ENV)
    if env:
        return parse_scheduler(env, SCHEDULER_ENV, None, workers, threads)
    return parse_scheduler("local", "--scheduler", None, workers, threads)


# ------------------------------------------------------------------------------------------------
# the session: one scheduler per command
_session: "_Dask | None" = None
_cache: dict = {}
CACHE_ENTRIES = 2


def worker_cache(key, build: Callable[[], Any]):
    """``build()`` once per process and key (module doc); the oldest entries go past CACHE_ENTRIES."""
    if key in _cache:
        return _cache[key]
    while len(_cache) >= CACHE_ENTRIES:
        _cache.pop(next(iter(_cache)))
    _cache[key] = value = build()
    return value


def _clear_cache() -> None:
    _cache.clear()


class _Dask:
    def __init__(self, spec: Scheduler, client, cluster):
        self.spec, self.client, self.cluster = spec, client, cluster
        self.tasks = 0

    def workers(self) -> int:
        if self.spec.kind == "processes":
            return self.spec.workers
        try:
            return max(1, len(self.client.scheduler_info().get("workers", {})))
        except Exception:  # the count only scales a reported time
            return 1

    def lost(self, e: BaseException) -> LoomError:
        where = self.spec.address or "the LocalCluster"
        why = " ".join(str(e).split())[:160] or "connection closed"
        return LoomError(None, "--scheduler", f"lost the Dask scheduler at {where} ({type(e).__name__}: {why})")


def _worker_env(spec: Scheduler) -> dict:
    env = {"NUMBA_NUM_THREADS": str(spec.threads_per_worker), "OMP_NUM_THREADS": "1",
           "PYTHONHASHSEED": os.environ.get("PYTHONHASHSEED", "0"), "MPLBACKEND": "Agg"}
    for k in ("LOOMLIGHT_NUMBA_CACHE_ROOT", "NUMBA_CACHE_DIR", "LOOMLIGHT_TASK_SLEEP"):
        if k in os.environ:
            env[k] = os.environ[k]
    return env


def probe_address(address: str, timeout: float) -> None:
    """Open and close a TCP connection to ``tcp://HOST:PORT``: a refused connection, an unknown host or
    an unreachable network raises its OSError at once (Dask's client retries those until its timeout);
    only silence waits out ``timeout`` seconds (``TimeoutError``)."""
    import socket

    host, _, port = address[len("tcp://"):].rpartition(":")
    with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
        pass


@contextmanager
def session(spec: Scheduler | None):
    """Run the block's ``run_tasks`` on ``spec`` (module doc). Local: nothing is started."""
    global _session
    if spec is None or not spec.distributed:
        try:
            yield None
        finally:
            _clear_cache()
        return
    import logging
    import tempfile

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise LoomError(None, "--scheduler", "needs dask.distributed: pip install 'loomlight[dask]' "
                        "(make setup installs it)") from None
    for name in ["distributed", *logging.root.manager.loggerDict]:  # failures come back as one-line errors
        if name.split(".")[0] == "distributed":
            logging.getLogger(name).setLevel(logging.CRITICAL)
    cluster = client = None
    try:
        if spec.kind == "processes":
            scratch = tempfile.mkdtemp(prefix="loomlight-dask-")
            cluster = LocalCluster(n_workers=spec.workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.ERROR,
                                   local_directory=scratch, env=_worker_env(spec))
            client = Client(cluster, set_as_default=False)
        else:
            try:
                timeout = float(os.environ.get(CONNECT_TIMEOUT_ENV) or 10)
                probe_address(spec.address, timeout)
                client = Client(spec.address, timeout=timeout, set_as_default=False)
            except (OSError, TimeoutError) as e:
                raise LoomError(None, "--scheduler", f"cannot reach the Dask scheduler at {spec.address} "
                                f"({type(e).__name__}: {' '.join(str(e).split())[:200]})") from None
        link = getattr(client, "dashboard_link", None)
        info(f"scheduler: {spec.describe()}" + (f"; Dask dashboard {link}" if link else ""))
        _session = _Dask(spec, client, cluster)
        yield _session
    finally:
        _session = None
        _clear_cache()
        for x in (client, cluster):
            if x is not None:
                try:
                    x.close()
                except Exception:  # a lost scheduler cannot be closed cleanly; nothing is left to free
                    pass


def distributed() -> bool:
    """Whether a Dask session is open (``run_tasks`` sends tasks to workers)."""
    return _session is not None


def worker_count() -> int:
    """Workers of the open session (1 without one)."""
    return _session.workers() if _session is not None else 1


def _call(task: ChunkTask):
    task_pause()
    return task()


def run_tasks(tasks: Sequence[ChunkTask], description: str) -> list:
    """Run the tasks on the session's scheduler (local: here, in order); results in task order."""
    if _session is None:
        results = []
        with progress(description, len(tasks)) as advance:
            for t in tasks:
                results.append(t())
                advance()
        return results
    return _run_dask(_session, list(tasks), description)


def _run_dask(s: _Dask, tasks: list, description: str) -> list:
    from distributed import as_completed

    s.tasks += 1
    prefix = f"loomlight-{os.getpid()}-{s.tasks}"
    try:
        futures = s.client.map(_call, tasks, key=[f"{prefix}-{i}" for i in range(len(tasks))], pure=False)
        with progress(description, len(tasks)) as advance:
            for _ in as_completed(futures, loop=s.client.loop):
                advance()
        return s.client.gather(futures)
    except LoomError:
        raise
    except (OSError, TimeoutError) as e:  # CommClosedError is an OSError; so is a refused reconnect
        raise s.lost(e) from None
    except Exception as e:
        from concurrent.futures import CancelledError

        if isinstance(e, CancelledError) or type(e).__name__ in ("CancelledError", "FutureCancelledError"):
            raise s.lost(e) from None
        raise


def task_pause() -> None:
    """Tests: ``LOOMLIGHT_TASK_SLEEP`` seconds of sleep at a task's start, so a test can kill a worker
    while tasks are running."""
    t = os.environ.get("LOOMLIGHT_TASK_SLEEP")
    if t:
        import time

        time.sleep(float(t))


def open_for_chunk(store_path, name: str):
    """Open one array of an artifact under construction for writing its chunks."""
    import zarr

    return zarr.open_array(str(store_path), path=name, mode="r+")
