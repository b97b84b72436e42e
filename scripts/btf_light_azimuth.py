"""What a btf light grid misses: the fibres' mean radiance against the light's azimuth (``make btf-azimuth``).

The flat 1/4 satin of ``make btf-sweep`` (the tiling ``out/prt/flat14_tiling.zarr``, exemplar 1, the scene
``data/scenes/flat_satin.toml``) seen by a far camera (20 units away, fov 2.86 degrees: every pixel looks along
one direction) along a view of the 8 x 8 hemisphere grid (``stages.core.btf.hemisphere_grid``; ring 1,
azimuth 5 by default), lit by a directional light on a grid ring (ring 4: 64 degrees from the normal) whose
azimuth steps round the circle, single scattering only (depth 1, where the fibres' glints dominate):

- **fiberpath**: the image mean of each step (``--step`` degrees, ``--spp`` samples a pixel);
- **the btf acquisition** of the same exemplar at that depth (``precompute btf --resolution 16 --max-depth 1``,
  ``--acq-spp`` samples a texel and view), three times: ``--directions grid`` (point samples at the grid's
  directions) and ``--directions cell`` (the default: cell averages) on the 8 x 8 light grid, and cell averages
  over 15 x 15 half-vector cells (``--light-coords half``), each read as the renderer reads the tabulated model
  (bilinear on the light grid, ``stages.core.btf.grid_weights``; on the half-vector cells at the half vector of
  light and view, ``stages.core.btf.half_row``), times the light's irradiance, averaged over the texels with
  their alpha, at the grid view itself (no view interpolation).

Writes ``OUT/azimuth.json`` (the steps and the three curves) and ``OUT/btf_light_azimuth.png``; ``--docs`` copies
the picture to docs/img/. About 5 minutes on 2 cores (72 renders of 96 x 72 and three acquisitions of 20-40 s).

    .venv/bin/python scripts/btf_light_azimuth.py -o out/btf/azimuth [--step 5] [--spp 16] [--docs]
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LL = str(ROOT / ".venv" / "bin" / "loomlight")
TILING = "out/prt/flat14_tiling.zarr"
SCENE = ROOT / "data" / "scenes" / "flat_satin.toml"
EXEMPLAR = 1
GRID = (8, 8)
IRRADIANCE = 3.0
TARGET = (0.75, 0.75, 0.09)      # the patch's middle (the scene camera's target)
DISTANCE = 20.0
FOV = 2.86                       # degrees: about one unit of cloth across at DISTANCE


def ring_direction(ring: int, azimuth_deg: float) -> tuple[float, float, float]:
    """Unit direction on ring ``ring`` of the hemisphere grid at an azimuth (``stages.core.btf.cell_direction``
    with the ring's centre, u1 past the cell when the azimuth is: cos and sin wrap)."""
    from stages.core.btf import cell_direction

    return cell_direction(ring * GRID[1], GRID[0], GRID[1], 0.5, azimuth_deg / 360.0 * GRID[1])


def _run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"btf_light_azimuth: {' '.join(cmd)} failed:\n{proc.stderr.strip()[-2000:]}")


def fiberpath_curve(out: Path, view: np.ndarray, light_ring: int, step: float, spp: int) -> list[list[float]]:
    """[(azimuth degrees, image mean)] of fiberpath at depth 1, the far camera along ``view``."""
    from pipeline.images import read_exr
    from pipeline.toml_file import dumps_toml

    doc = tomllib.loads(SCENE.read_text())
    origin = [float(t + DISTANCE * v) for t, v in zip(TARGET, view)]
    doc["camera"] = {"origin": origin, "target": list(TARGET), "up": [0.0, 0.0, 1.0], "fov": FOV,
                     "width": 96, "height": 72}
    curve = []
    for deg in np.arange(0.0, 360.0, step):
        toward = ring_direction(light_ring, float(deg))
        doc["lights"] = [{"type": "directional", "direction": [-float(x) for x in toward], "irradiance": IRRADIANCE}]
        scene = out / "scene.toml"
        scene.write_text(dumps_toml(doc))
        exr = out / "fiberpath.exr"
        _run([LL, "render", str(scene), "-o", str(exr), "--method", "fiberpath", "--fibers", TILING,
              "--max-depth", "1", "--spp", str(spp), "--threads", "2"])
        curve.append([float(deg), float(read_exr(exr)[0].astype(np.float64).mean())])
        print(f"  fiberpath, light azimuth {deg:5.1f}: {curve[-1][1]:.5f}", flush=True)
    return curve


def table_curve(artifact: Path, view_index: int, light_ring: int) -> list[list[float]]:
    """[(azimuth degrees, mean)] of an acquisition read bilinearly on the light grid at the grid view."""
    import zarr

    from stages.core.btf import grid_weights

    g = zarr.open_group(str(artifact), mode="r")
    S = np.asarray(g["samples"][0], dtype=np.float64)      # (res, res, V, L, 3)
    A = np.asarray(g["alpha"][0], dtype=np.float64)        # (res, res, V)
    per_light = IRRADIANCE * (A[:, :, view_index, None, None] * S[:, :, view_index]).mean(axis=(0, 1)).mean(axis=-1)
    curve = []
    for deg in np.arange(0.0, 360.0, 1.0):
        i0, i1, i2, i3, w0, w1, w2, w3 = grid_weights(GRID[0], GRID[1], *ring_direction(light_ring, float(deg)))
        curve.append([float(deg), float(w0 * per_light[i0] + w1 * per_light[i1] + w2 * per_light[i2]
                                         + w3 * per_light[i3])])
    return curve


def half_curve(artifact: Path, view_index: int, light_ring: int) -> list[list[float]]:
    """[(azimuth degrees, mean)] of a half-vector acquisition read at the grid view (``stages.core.btf.half_row``)."""
    import zarr

    from stages.core.btf import half_cell_geometry, half_row, half_weights, hemisphere_grid

    g = zarr.open_group(str(artifact), mode="r")
    nx, ny = (int(x) for x in g.attrs["summary"]["light_grid"])
    S = np.asarray(g["samples"][0], dtype=np.float64)      # (res, res, V, L, 3)
    A = np.asarray(g["alpha"][0], dtype=np.float64)        # (res, res, V)
    per_light = (A[:, :, view_index, None, None] * S[:, :, view_index]).mean(axis=(0, 1))   # (L, 3)
    table = np.zeros((1, GRID[0] * GRID[1], nx * ny, 3))
    table[0, view_index] = per_light
    valid = half_cell_geometry(GRID[0], GRID[1], nx, ny, True).valid
    view = hemisphere_grid(*GRID)[view_index]
    curve = []
    for deg in np.arange(0.0, 360.0, 1.0):
        light = ring_direction(light_ring, float(deg))
        q = half_weights(nx, ny, *light, *view)
        r = half_row(table, valid, 0, view_index, *q)
        curve.append([float(deg), IRRADIANCE * float(np.mean(r[:3]))])
    return curve


def plot(data: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fp = np.array(data["fiberpath"])
    fig, ax = plt.subplots(figsize=(8, 3.6), dpi=110)
    ax.plot(fp[:, 0], fp[:, 1], "k.-", lw=1.2, ms=4, label=f"fiberpath (the fibres), {data['step']:g}° steps")
    for key, label, style in (("grid", "8×8 grid, point samples (--directions grid), read bilinearly", "C0-"),
                              ("cell", "8×8 grid, cell averages (the default), read bilinearly", "C3-"),
                              ("half", "15×15 half-vector cells, cell averages (--light-coords half)", "C2-")):
        if key not in data:
            continue
        c = np.array(data[key])
        ax.plot(c[:, 0], c[:, 1], style, lw=1.5, label=label)
    for k in range(GRID[1] + 1):
        ax.axvline(360.0 / GRID[1] * k, color="0.85", lw=0.8, zorder=0)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.set_xlabel(f"light azimuth (degrees; light {data['light_theta_deg']:.0f}° from the normal; "
                  "grey lines: the 8×8 grid's azimuth cells)")
    ax.set_ylabel("mean radiance, single scattering")
    ax.set_title("Flat 1/4 satin seen along a grid view: the texture's mean against the light's azimuth",
                 fontsize=10)
    ax.legend(fontsize=7.5, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "out" / "btf" / "azimuth")
    ap.add_argument("--view", default="1,5", help="grid view RING,AZIMUTH (8 x 8 grid)")
    ap.add_argument("--light-ring", type=int, default=4, help="the light's grid ring (0: overhead, 7: grazing)")
    ap.add_argument("--step", type=float, default=5.0, help="degrees between the fiberpath renders")
    ap.add_argument("--spp", type=int, default=16, help="fiberpath samples a pixel")
    ap.add_argument("--acq-spp", type=int, default=64, help="acquisition samples a texel and view")
    ap.add_argument("--docs", action="store_true", help="copy the picture to docs/img/btf_light_azimuth.png")
    a = ap.parse_args(argv)
    if not (ROOT / TILING).is_dir():
        sys.exit(f"btf_light_azimuth: {TILING} is missing; make prt-sweep (or its tiling rule) builds it")
    vi, vj = (int(x) for x in a.view.split(","))
    if not (0 <= vi < GRID[0] and 0 <= vj < GRID[1] and 0 <= a.light_ring < GRID[0]):
        sys.exit(f"btf_light_azimuth: --view and --light-ring must lie on the {GRID[0]}x{GRID[1]} grid")
    a.out.mkdir(parents=True, exist_ok=True)
    data = {"view": [vi, vj], "light_ring": a.light_ring, "step": a.step, "spp": a.spp, "acq_spp": a.acq_spp,
            "light_theta_deg": math.degrees(math.acos(ring_direction(a.light_ring, 0.0)[2]))}
    for directions in ("grid", "cell"):
        art = a.out / f"flat14_d1_{directions}.zarr"
        print(f"acquisition ({directions}): {art}", flush=True)
        _run([LL, "precompute", "btf", TILING, "-o", str(art), "--exemplar", str(EXEMPLAR), "--resolution", "16",
              "--max-depth", "1", "--spp", str(a.acq_spp), "--directions", directions])
        data[directions] = table_curve(art, vi * GRID[1] + vj, a.light_ring)
    art = a.out / "flat14_d1_half.zarr"
    print(f"acquisition (half-vector cells): {art}", flush=True)
    _run([LL, "precompute", "btf", TILING, "-o", str(art), "--exemplar", str(EXEMPLAR), "--resolution", "16",
          "--max-depth", "1", "--spp", str(a.acq_spp), "--light-coords", "half"])
    data["half"] = half_curve(art, vi * GRID[1] + vj, a.light_ring)
    view = np.array(ring_direction(vi, (vj + 0.5) * 360.0 / GRID[1]))      # the grid view (vi, vj) itself
    data["fiberpath"] = fiberpath_curve(a.out, view, a.light_ring, a.step, a.spp)
    (a.out / "azimuth.json").write_text(json.dumps(data, indent=1))
    png = a.out / "btf_light_azimuth.png"
    plot(data, png)
    if a.docs:
        shutil.copyfile(png, ROOT / "docs" / "img" / "btf_light_azimuth.png")
    print(f"wrote {a.out / 'azimuth.json'} and {png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
