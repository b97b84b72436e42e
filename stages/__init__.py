"""loomlight's science: pure numba kernels on arrays, one package per stage plus ``core``.

Nothing under ``stages`` does I/O, reads configuration, draws progress or imports ``pipeline``.
Importing it makes sure numba has a writable, project-local cache directory.
"""
import hashlib as _hashlib
import os as _os
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
