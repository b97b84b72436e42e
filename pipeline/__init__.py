"""loomlight's plumbing: CLI, scene files, artifact store, one runner per stage."""
import stages as _stages  # noqa: F401  (sets NUMBA_CACHE_DIR before numba is imported)

__version__ = "0.1.0"
