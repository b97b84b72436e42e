"""Compilation notices: no minute of numba compilation passes with nothing on screen.

numba compiles a kernel the first time this code runs on a machine (its cache directory is keyed by the
kernel sources, ``stages/__init__.py``), and once per new typing of its arguments; loomlight's render
kernels take minutes to compile (the Makefile: procedural ``volpath`` about 3.5 on a cold cache), during
which no bar moves. ``watch()`` registers a listener on numba's ``numba:compile`` event, which numba fires only when it
compiles (a kernel loaded from the cache fires none): that is the cold-cache test, exact and free.
After ``DELAY_S`` of compiling, a spinner (off a terminal, a line: ``pipeline.progress``) says

    compiling volpath render: render_tile_borrowed (first run of this code on this machine; ~3 min 28 s last time)

and at the end one line says how long it took. The time is kept per kernel (and integrator class) in
``compile_times.json`` beside the numba cache's directories, for the next estimate (a code change
compiles again, in about the same time); of a kernel never timed here it says that it can take minutes.
``group(label)`` names what compiles inside it (``volpath render``, ``tables``); without one the notice
names the kernel's module.

``watch()`` is called by the command line for every command that runs (``pipeline.cli.main``; not for
``--help``, ``--version``, ``info`` or ``docs``: it imports numba, and those stay fast), and by the runners
that compile (render and every stage it builds, tables, realize, precompute svf / iirtf / btf) for
callers of the API.
"""
from __future__ import annotations

import json
import os
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

from . import progress

DELAY_S = 2.0            # compilations shorter than this say nothing (the stage's own spinner covers them)
RECORD_MIN_S = 1.0       # and are not recorded
_state = threading.local()
_lock = threading.Lock()
_listener = None
_groups: list[str] = []


def times_file() -> Path | None:
    """Where compile times are kept: beside the numba cache's per-source directories."""
    d = os.environ.get("NUMBA_CACHE_DIR")
    return Path(d).parent / "compile_times.json" if d else None


def _read_times() -> dict:
    f = times_file()
    try:
        data = json.loads(f.read_text()) if f is not None else {}
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def record(key: str, seconds: float) -> None:
    """Keep ``seconds`` as the time of ``key`` for the next estimate (``estimate_s``)."""
    f = times_file()
    if f is None:
        return
    with _lock:
        data = _read_times()
        data[key] = round(float(seconds), 3)
        tmp = f.with_name(f"{f.name}.{os.getpid()}.tmp")
        try:
            f.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
            os.replace(tmp, f)
        except OSError:  # a read-only cache: estimates only
            tmp.unlink(missing_ok=True)


def estimate_s(key: str) -> float | None:
    """Seconds the kernel ``key`` took to compile last time on this machine; None if never timed."""
    t = _read_times().get(key)
    return float(t) if isinstance(t, (int, float)) and t > 0 else None


def kernel_key(dispatcher, args=()) -> tuple[str, str, str]:
    """(key, module, name) of a compilation: the kernel's module and name, and the class of an integrator
    (a namedtuple) passed first, whose kernels differ most."""
    f = getattr(dispatcher, "py_func", None)
    name = getattr(f, "__qualname__", None) or getattr(dispatcher, "__name__", "kernel")
    module = getattr(f, "__module__", None) or "?"
    key = f"{module}.{name}"
    if args:
        cls = getattr(args[0], "instance_class", None)
        if cls is not None:
            key += f"[{cls.__name__}]"
    return key, module, name


def describe(module: str, name: str) -> str:
    """What compiles, for people: the group it runs in (else its module) and the kernel."""
    return f"{_groups[-1] if _groups else module}: {name}"


def notice(what: str, est: float | None) -> str:
    how_long = f"~{progress.clock(est)} last time" if est else "can take minutes"
    return f"compiling {what} (first run of this code on this machine; {how_long})"


class _Compiling:
    """The outermost compilation in progress: its notice appears after ``DELAY_S``."""

    def __init__(self, key: str, what: str):
        self.key, self.what = key, what
        self.t0 = time.perf_counter()
        self.work = None
        self.ended = False
        self.guard = threading.Lock()
        self.timer = None
        if DELAY_S <= 0:
            self.show()
        else:
            self.timer = threading.Timer(DELAY_S, self.show)
            self.timer.daemon = True
            self.timer.start()

    def show(self):
        with self.guard:
            if self.ended:
                return
            text = notice(self.what, estimate_s(self.key))
            self.work = progress.begin(text, None, announce=text if progress.mode() == "plain" else None)

    def finish(self):
        if self.timer is not None:
            self.timer.cancel()
        with self.guard:
            self.ended = True
            took = time.perf_counter() - self.t0
            if self.work is not None:
                self.work.done = f"compiled {self.what} in {progress.clock(took)}"
                self.work.printed = True
                progress.end(self.work)
        if took >= RECORD_MIN_S:
            record(self.key, took)


def _on_start(event) -> None:
    depth = getattr(_state, "depth", 0)
    _state.depth = depth + 1
    data = event.data or {}
    key, module, name = kernel_key(data.get("dispatcher"), data.get("args") or ())
    if depth == 0:
        _state.current = _Compiling(key, describe(module, name))
    if _log_path is not None:
        _log_start(key, data.get("args") or ())


def _on_end(event) -> None:
    _state.depth = max(0, getattr(_state, "depth", 1) - 1)
    if _log_path is not None:
        _log_end()
    if _state.depth == 0 and getattr(_state, "current", None) is not None:
        current, _state.current = _state.current, None
        current.finish()


# ---- the compile log of ``make compile-report`` (bench/compile_report.py) ------------------------------
# With ``LOOMLIGHT_COMPILE_LOG`` set to a file, every compilation appends one JSON line to it: the kernel,
# the signature it was typed with, its seconds in all and without the kernels it compiled inside it
# (``self_s``), and who asked: the kernel it was compiled for (``parent``), else the first frame of
# loomlight's code outside numba (``caller``), and the command or test file running (``context``).

LOG_ENV = "LOOMLIGHT_COMPILE_LOG"
_log_path = os.environ.get(LOG_ENV) or None


def _command_context(argv: list[str]) -> str:
    """``loomlight render --method volpath`` of a command line: the program, its subcommand words and the
    method, without paths and settings."""
    if not argv:
        return "python"
    words = [Path(argv[0]).name]
    for a in argv[1:]:
        if a.startswith("-") or "/" in a or "." in a:
            break
        words.append(a)
    if "--method" in argv[:-1]:
        words += ["--method", argv[argv.index("--method") + 1]]
    return " ".join(words)


context = os.environ.get("LOOMLIGHT_COMPILE_CONTEXT") or _command_context(list(sys.argv))
_OWN_DIRS = ("pipeline", "tests", "bench", "stages")


def _caller() -> str:
    """The innermost frame of loomlight's Python code (not a numba kernel being typed) that asked."""
    f = sys._getframe(3)
    root = str(Path(__file__).resolve().parent.parent)
    while f is not None:
        fn = f.f_code.co_filename
        if fn.startswith(root) and "/numba/" not in fn and Path(fn).name != "compilation.py":
            rel = Path(fn).resolve().relative_to(root)
            if rel.parts and rel.parts[0] in _OWN_DIRS:
                return f"{rel}:{f.f_lineno} ({f.f_code.co_name})"
        f = f.f_back
    return "?"


def _log_start(key: str, args) -> None:
    stack = getattr(_state, "log_stack", None)
    if stack is None:
        stack = _state.log_stack = []
    sig = ", ".join(str(a) for a in args)
    asked = stack[-1]["kernel"] if stack else None
    stack.append({"kernel": key, "signature": sig, "parent": asked,
                  "caller": None if asked else _caller(), "t0": time.perf_counter(), "children_s": 0.0})


def _log_end() -> None:
    stack = getattr(_state, "log_stack", None)
    if not stack:
        return
    rec = stack.pop()
    total = time.perf_counter() - rec.pop("t0")
    children = rec.pop("children_s")
    if stack:
        stack[-1]["children_s"] += total
    rec.update(total_s=round(total, 4), self_s=round(max(0.0, total - children), 4),
               context=context, pid=os.getpid())
    line = json.dumps(rec) + "\n"
    with _lock:
        try:
            with open(_log_path, "a") as fh:   # one write of one line: whole lines from every process
                fh.write(line)
        except OSError:
            pass


def watch() -> None:
    """Register the compilation listener once per process (module doc)."""
    global _listener
    if _listener is not None:
        return
    from numba.core import event as ev

    class Listener(ev.Listener):
        def on_start(self, event):
            _on_start(event)

        def on_end(self, event):
            _on_end(event)

    _listener = Listener()
    ev.register("numba:compile", _listener)


@contextmanager
def group(label: str):
    """Compilations inside the block are named ``label`` (``volpath render``, ``tables``)."""
    _groups.append(label)
    try:
        yield
    finally:
        _groups.pop()
