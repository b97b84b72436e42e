"""loomlight's science: pure numba kernels on arrays, one package per stage plus ``core``.

Nothing under ``stages`` does I/O, reads configuration, draws progress or imports ``pipeline``.
Importing it makes sure numba has a writable, project-local cache directory.
"""
import os as _os
from pathlib import Path as _Path


def _default_numba_cache() -> str:
    local = _Path(__file__).resolve().parents[1] / ".numba_cache"
    try:
        local.mkdir(exist_ok=True)
        if _os.access(local, _os.W_OK):
            return str(local)
    except OSError:
        pass
    fallback = _Path.home() / ".cache" / "loomlight" / "numba"
    fallback.mkdir(parents=True, exist_ok=True)
    return str(fallback)


_os.environ.setdefault("NUMBA_CACHE_DIR", _default_numba_cache())
