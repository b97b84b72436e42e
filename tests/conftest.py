"""Shared test fixtures (paths and reference data: ``tests/helpers.py``). Tests mirror the code:
``tests/core/<subject>``, ``tests/<stage>``, ``tests/pipeline``; every sampling routine goes through
``tests/chisquare.py``."""
import os

import pytest

from tests.helpers import ROOT

os.environ.setdefault("LOOMLIGHT_NUMBA_CACHE_ROOT", str(ROOT / ".numba_cache"))
import stages  # noqa: F401  (sets NUMBA_CACHE_DIR, keyed by the kernel sources, before numba loads)

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("LOOMLIGHT_PROGRESS", "0")  # no bars or compilation notices in captured output
# albedo curves a test measures (pipeline/dye.py) go to a scratch directory, never the user's ~/.cache
os.environ.setdefault("LOOMLIGHT_CACHE_DIR", str(ROOT / ".pytest_cache" / "loomlight"))


if os.environ.get("LOOMLIGHT_COMPILE_LOG"):   # make compile-report: every compilation, by test file
    from pipeline import compilation

    compilation.watch()

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(item):
        compilation.context = item.nodeid.split("::")[0]


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


# Test files that compile the same large kernel families. Under ``-n 2 --dist loadfile`` (``make test``)
# two workers that start such files at the same time both compile the family: the exact procedural
# lookups (``lookup_points``, ``fringe_occupancy``, ``sample_all``) cost 100-170 s of compilation each
# time on a cold numba cache, and were compiled twice in every clean run. One work unit per group
# keeps them on one worker, which compiles the family once and serves the rest from memory. The
# hostile-input workspace builds tables too (a cold clean run: 8:34-9:25 with it in the group, 10:26-10:55
# without, 2026-12-03).
SHARED_COMPILE = {
    "tests/procedural/test_tables_lookup.py": "procedural-lookups",
    "tests/render/test_volpath.py": "procedural-lookups",
    "tests/hostile/test_hostile.py": "procedural-lookups",
    "tests/hostile/test_round2_leftovers.py": "procedural-lookups",   # builds tables and realizes too
}


def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with the files of ``SHARED_COMPILE`` grouped into one work unit each."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class SharedCompileScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid):
            scope = super()._split_scope(nodeid)
            return SHARED_COMPILE.get(scope, scope)

    return SharedCompileScheduling(config, log)
