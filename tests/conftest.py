"""Shared test fixtures. ../shared is reference material: tests that use it skip when it is absent."""
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("LOOMLIGHT_NUMBA_CACHE_ROOT", str(ROOT / ".numba_cache"))
import stages  # noqa: E402,F401  (sets NUMBA_CACHE_DIR, keyed by the kernel sources, before numba loads)
os.environ.setdefault("MPLBACKEND", "Agg")
SHARED = ROOT.parent / "shared"
DATA = ROOT / "data"

# the gentle swatch (exact lookups): scene text of the lookups' exactness and frame-sample tests
EXACTNESS_SWATCH = (DATA / "scenes" / "gentle_swatch.toml").read_text()


def shared_file(rel: str) -> Path:
    p = SHARED / rel
    if not p.exists():
        pytest.skip(f"reference file ../shared/{rel} is not present (../shared is reference material, absent on this machine)")
    return p


@pytest.fixture
def cli(tmp_path):
    """Run the loomlight CLI in-process: returns (exit code, stdout, stderr)."""
    from pipeline.cli import main

    def run(*args):
        import contextlib
        import io

        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main([str(a) for a in args])
        return code, out.getvalue(), err.getvalue()

    return run


_GL = None


@pytest.fixture
def offscreen_gl():
    """Skip (with the reason) where pyvista cannot render off-screen; probed once in a subprocess,
    since forcing a missing OpenGL backend kills the process instead of raising."""
    global _GL
    if _GL is None:
        import subprocess
        import sys

        probe = subprocess.run([sys.executable, "-c",
                                "import os; os.environ.setdefault('VTK_DEFAULT_OPENGL_WINDOW','vtkEGLRenderWindow');"
                                "import pyvista as pv; p = pv.Plotter(off_screen=True); p.add_mesh(pv.Sphere());"
                                "p.screenshot('/dev/null')"], capture_output=True)
        _GL = probe.returncode == 0
    if not _GL:
        pytest.skip("no off-screen OpenGL for pyvista on this machine (EGL/OSMesa missing)")
