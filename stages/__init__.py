"""loomlight's science: pure numba kernels on arrays, one package per stage plus ``core``.

Nothing under ``stages`` does I/O, reads configuration, draws progress or imports ``pipeline``.
Importing it makes sure numba has a writable, project-local cache directory, and that numba's inliner,
when numba loads it, copies inlined functions the faster way (``stages.core.inline_copy``); importing
``stages`` itself does not import numba.
"""
import hashlib as _hashlib
import os as _os
import sys as _sys
from pathlib import Path as _Path


def _source_key() -> str:
    """Hash of every kernel source file. numba's cache only checks the timestamp of a function's own
    file, not of the kernels it calls in other files, so the cache lives in a directory named after
    the sources: changed code never runs stale machine code."""
    h = _hashlib.sha256()
    here = _Path(__file__).resolve().parent
    for f in sorted(here.rglob("*.py")):
        h.update(str(f.relative_to(here)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _default_numba_cache() -> str:
    key = _source_key()
    local = _Path(__file__).resolve().parents[1] / ".numba_cache" / key
    try:
        local.mkdir(parents=True, exist_ok=True)
        if _os.access(local, _os.W_OK):
            return str(local)
    except OSError:
        pass
    fallback = _Path.home() / ".cache" / "loomlight" / "numba" / key
    fallback.mkdir(parents=True, exist_ok=True)
    return str(fallback)


if "LOOMLIGHT_NUMBA_CACHE_ROOT" in _os.environ:  # set by the Makefile and tests: a root, keyed below
    _os.environ["NUMBA_CACHE_DIR"] = str(_Path(_os.environ["LOOMLIGHT_NUMBA_CACHE_ROOT"]) / _source_key())
else:
    _os.environ.setdefault("NUMBA_CACHE_DIR", _default_numba_cache())


_INLINER = "numba.core.inline_closurecall"


class _PatchInliner:
    """A finder that lets numba load its inliner as usual, then ``stages.core.inline_copy.install``s it."""

    def find_spec(self, name, path, target=None):
        if name != _INLINER:
            return None
        from importlib.machinery import PathFinder

        _sys.meta_path.remove(self)
        spec = PathFinder.find_spec(name, path, target)
        if spec is None or spec.loader is None:
            return spec
        load = spec.loader.exec_module

        def exec_module(module):
            load(module)
            from .core.inline_copy import install

            install(module)

        spec.loader.exec_module = exec_module
        return spec


if _INLINER in _sys.modules:
    from .core.inline_copy import install as _install

    _install(_sys.modules[_INLINER])
elif not any(isinstance(f, _PatchInliner) for f in _sys.meta_path):
    _sys.meta_path.insert(0, _PatchInliner())
