"""Compile ahead of time: the bundled scenes' commands at the smallest sizes, once per method.

numba compiles each kernel the first time it runs on a machine (``pipeline.compilation``), then loads it
from its cache. ``loomlight warmup`` pays that once, up front: it runs, in a scratch directory and in this
process, the commands ``make demo`` runs for each asked method (``METHOD_STEPS``) on the demo's scenes, at
pictures of a few pixels and precomputes of a few samples, so that every kernel those commands compile is
compiled with the same argument types as in a real run. What it writes is thrown away; the numba cache
keeps the compiled kernels. A scene of another kind (another light type, another medium) can still compile
a variant of an integrator on its first render; the demo's kinds are the common ones.

The plan is the union of the methods' steps in order, each step once (``plan``): volpath and fiberpath
both need the demo's yarns, prt and btf both the damask's tiling.
"""
from __future__ import annotations

import contextlib
import io
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "data" / "scenes"
DEMO = str(SCENES / "demo.toml")
DAMASK = str(SCENES / "draped_damask.toml")
KNIT = str(SCENES / "knit.toml")
TILING = str(ROOT / "data" / "tilings" / "damask.toml")
TINY = ("--width", "8", "--height", "6", "--spp", "1")   # a picture of 48 samples: the kernels, not the light


@dataclass(frozen=True)
class Step:
    """One command of the plan: a name for the bar and its arguments, ``{d}`` the scratch directory."""
    name: str
    args: tuple[str, ...]


_INGEST = Step("ingest the demo swatch", ("ingest", DEMO, "-o", "{d}/yarns.zarr"))
_REALIZE = Step("realize its fibres", ("realize", "{d}/yarns.zarr", "-o", "{d}/fibers.zarr"))
_TILE = Step("tile the damask", ("tile", TILING, "-o", "{d}/tiling.zarr"))
_KNIT = Step("ingest the knit", ("ingest", KNIT, "-o", "{d}/knit_yarns.zarr"))

METHOD_STEPS: dict[str, tuple[Step, ...]] = {
    "volpath": (
        _INGEST,
        Step("procedural tables", ("tables", "{d}/yarns.zarr", "-o", "{d}/tables.zarr")),
        Step("volpath, procedural, fibre cache", ("render", DEMO, "--method", "volpath", "--source", "procedural",
                                                  "--tables", "{d}/tables.zarr", *TINY, "-o", "{d}/vp.exr")),
        _REALIZE,
        Step("volpath, realized", ("render", DEMO, "--method", "volpath", "--source", "realized",
                                   "--fibers", "{d}/fibers.zarr", *TINY, "-o", "{d}/vpr.exr")),
    ),
    "fiberpath": (
        _INGEST, _REALIZE,
        Step("fiberpath, realized fibres", ("render", DEMO, "--method", "fiberpath", "--fibers", "{d}/fibers.zarr",
                                            *TINY, "-o", "{d}/fp.exr")),
        _TILE,
        Step("fiberpath, tiled cloth", ("render", DAMASK, "--method", "fiberpath", "--fibers", "{d}/tiling.zarr",
                                        *TINY, "-o", "{d}/fpt.exr")),
    ),
    "prt": (
        _TILE,
        Step("SVF precompute", ("precompute", "svf", "{d}/tiling.zarr", "-o", "{d}/svf.zarr", "--resolution", "8",
                                "--components", "4")),
        Step("IIRTF precompute", ("precompute", "iirtf", "{d}/tiling.zarr", "-o", "{d}/iirtf.zarr", "--order", "2",
                                  "--cell-factor", "8", "--paths", "2", "--light-sampling", "mis", "--layer-paths",
                                  "2", "--layer-bins", "1")),
        Step("prt", ("render", DAMASK, "--method", "prt", "--fibers", "{d}/tiling.zarr", "--set", "svf={d}/svf.zarr",
                     "--set", "iirtf={d}/iirtf.zarr", *TINY, "-o", "{d}/prt.exr")),
    ),
    "btf": (
        _TILE,
        # every exemplar the damask's block map uses (the render refuses a texture without one of them)
        Step("BTF acquisition, fit and table", ("precompute", "btf", "{d}/tiling.zarr", "-o", "{d}/btf_fit.zarr",
                                                "--resolution", "2", "--views", "2x2", "--lights", "2x2", "--spp",
                                                "1", "--model", "tabulated", "--clusters", "2", "--components", "2")),
        Step("btf", ("render", DAMASK, "--method", "btf", "--source", "tiling", "--fibers", "{d}/tiling.zarr",
                     "--set", "btf={d}/btf_fit.zarr", *TINY, "-o", "{d}/btf.exr")),
        Step("btf, tabulated", ("render", DAMASK, "--method", "btf", "--source", "tiling", "--fibers",
                                "{d}/tiling.zarr", "--set", "btf={d}/btf_fit.zarr", "--set", "model=tabulated", *TINY,
                                "-o", "{d}/btf_tabulated.exr")),
    ),
    "bysdf": (
        _INGEST, _REALIZE,
        Step("fit-bysdf", ("fit-bysdf", DEMO, "--yarns", "{d}/yarns.zarr", "--fibers", "{d}/fibers.zarr",
                           "-o", "{d}/fit.toml", "--width", "4", "--height", "3", "--spp", "1", "--ref-spp", "1",
                           "--iterations", "1")),
        _KNIT,
        Step("bysdf", ("render", KNIT, "--method", "bysdf", "--set", "yarns={d}/knit_yarns.zarr",
                       "--set", "params={d}/fit.toml", *TINY, "-o", "{d}/bysdf.exr")),
    ),
}
METHODS = tuple(METHOD_STEPS)


def plan(methods) -> list[Step]:
    """The steps of ``methods`` in order, each once."""
    out: list[Step] = []
    for m in methods:
        for s in METHOD_STEPS[m]:
            if s not in out:
                out.append(s)
    return out


def estimate_key(methods) -> str:
    return "warmup[" + ",".join(sorted(methods)) + "]"


def run(methods, on_step=None) -> float:
    """Run the plan of ``methods`` in a scratch directory; ``on_step(k, step)`` before each step. Returns the
    seconds it took. A step that fails raises a RuntimeError (a loomlight bug: the plan's inputs are bundled) with
    its command and its last output lines."""
    from .cli import main

    steps = plan(methods)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="loomlight-warmup-") as d:
        for k, step in enumerate(steps):
            if on_step is not None:
                on_step(k, step)
            args = [a.replace("{d}", d) for a in step.args]
            out = io.StringIO()   # the commands' "wrote ..." lines; their notices and bars go to stderr as usual
            with contextlib.redirect_stdout(out):
                code = main(args)
            if code != 0:
                tail = " | ".join(out.getvalue().strip().splitlines()[-3:])
                raise RuntimeError(f"warmup step {step.name!r} failed (exit {code}): "
                                   f"loomlight {' '.join(args)}: {tail}")
    return time.perf_counter() - t0
