"""The material chart and the colour check of the yarn-colour convention (pipeline/dye.py): ``make gallery``.

Every BCSDF preset x four yarn colours (white, red, blue, black) on the standard swatch
(data/scenes/chart_swatch.toml, one yarn type, its fibres realized once per colour):

- **chart**: fiberpath under the scene's studio lights, one labelled tile per (preset, colour), into
  ``OUT/material_chart.png`` (``--docs`` also copies it to docs/img/material_chart.png);
- **check**: under a uniform white sky of radiance 1 (the convention: a yarn's colour is what cloth of it
  shows under white diffuse light), the mean linear-RGB colour of the swatch: converged, by the analog walk
  of ``stages.render.integrators.albedo_walk`` through the same fibres with the same dyed BCSDF (the
  expectation fiberpath estimates, without its heavy-tailed weights; rays along the camera's axis onto the
  swatch's middle), and from renders (fiberpath, bysdf, realized volpath: mean of the cloth pixels, alpha =
  1); CIEDE2000 differences (linear sRGB -> Lab, D65; stages/evaluate/metrics.py) of the walk from the
  requested colour and of each render from the walk, into ``OUT/colours.json`` and a Markdown table
  ``OUT/colours.md``.

    .venv/bin/python scripts/colour_chart.py -o out/gallery [--presets cotton,silk] [--colours red,black]
        [--spp 64] [--sky-spp 256] [--docs] [--keep]

Warns (and with ``--strict`` exits 1) when a swatch (the walk) misses its colour by more than
``--tolerance`` (default 5) ΔE2000. ``--chart-only`` renders the chart alone.
"""
from __future__ import annotations

import argparse
import functools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENE = ROOT / "data" / "scenes" / "chart_swatch.toml"
COLOURS = {"white": (0.80, 0.80, 0.80), "red": (0.80, 0.22, 0.15), "blue": (0.12, 0.20, 0.60),
           "black": (0.04, 0.04, 0.04)}
SKY = '[[lights]]\ntype = "constant"\nradiance = 1.0\n'
CLOTH_ALPHA = 0.999          # pixels whose every sample met the cloth (no sky mixed in)
WALK_HALF_WIDTH = 0.15       # the walk's rays cross the swatch's middle 0.3 x 0.3 cm (of 0.6 cm)
WALK_RAYS = 20000
TILE_SCALE = 2


def loomlight(*args) -> None:
    exe = Path(sys.executable).parent / "loomlight"
    r = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"loomlight {' '.join(map(str, args))}: {r.stderr.strip() or r.stdout.strip()}")


def scene_text(colour, bcsdf: str, sky: bool) -> str:
    text = SCENE.read_text()
    text = text.replace("color = [0.80, 0.80, 0.80]", f"color = [{colour[0]}, {colour[1]}, {colour[2]}]")
    text = text.replace('bcsdf = "cotton"', f'bcsdf = "{bcsdf}"')
    if sky:
        head, tail = text.split("[[lights]]", 1)
        text = head + SKY + "\n[render]" + tail.split("[render]", 1)[1]
    return text


def cloth_mean(exr: Path):
    from pipeline.images import read_exr

    rgb, extra = read_exr(exr)
    cloth = extra["A"] >= CLOTH_ALPHA
    return rgb[cloth].astype(np.float64).mean(axis=0), int(cloth.sum())


@functools.lru_cache(maxsize=1)
def _fibre_scene(fibers: str):
    """(Fibers, FiberBVH) of a fibers artifact, built once for the presets that share one colour's fibres."""
    from pipeline.render_setup import load_fibers
    from stages.core.geometry.bvh import build_fiber_bvh

    f = load_fibers(fibers)
    return f, build_fiber_bvh(f.points, f.fiber_offsets, f.point_radius)[0]


def walk_mean(scene_path: Path, fibers: Path, bcsdf: str, colour, rays: int) -> list:
    """The converged mean colour of the swatch's middle under the white sky (module doc): per channel, the
    analog walk with every fibre's BCSDF dyed to ``colour`` (one yarn type: one row)."""
    from pipeline import dye
    from pipeline.bcsdf_presets import load_bcsdf_preset
    from pipeline.render_setup import SELF_WINDOW, ray_eps
    from pipeline.scene import load_scene
    from stages.render.integrators.albedo_walk import yarn_albedo

    scene = load_scene(scene_path)
    f, bvh = _fibre_scene(str(fibers))
    p = load_bcsdf_preset(bcsdf)
    row = dye.Dyer(scene).row(p, np.asarray(colour, np.float64), "default", bcsdf)
    mats = dye.dyed_bcsdf(p, np.repeat(row[3:6, None], 3, axis=1), row[0])
    cam = scene.camera
    d = np.asarray(cam["target"], np.float64) - np.asarray(cam["origin"], np.float64)
    d /= np.linalg.norm(d)
    half = WALK_HALF_WIDTH
    corner = np.array([-half, -half, 0.0]) - 5.0 * d
    a, _, _ = yarn_albedo(bvh, mats, corner, np.array([2 * half, 0.0, 0.0]), np.array([0.0, 2 * half, 0.0]), d,
                          rays, 1, ray_eps(f.points.min(axis=0), f.points.max(axis=0)), SELF_WINDOW, 1_000_000)
    return [round(float(v), 4) for v in a]


def delta_e(a, b) -> float:
    from stages.evaluate.metrics import delta_e2000_map

    return float(delta_e2000_map(np.asarray(a, np.float64).reshape(1, 1, 3),
                                 np.asarray(b, np.float64).reshape(1, 1, 3))[0, 0])


def fmt(v) -> str:
    return "/".join(f"{x:.3f}" for x in v)


def chart(tiles: dict, presets, colours, out: Path) -> None:
    from PIL import Image, ImageDraw

    from pipeline.images import to_srgb8

    first = Image.open(next(iter(tiles.values())))
    w, h = first.width * TILE_SCALE, first.height * TILE_SCALE
    left, top, gap = 96, 40, 6
    img = Image.new("RGB", (left + len(colours) * (w + gap), top + len(presets) * (h + gap)), (245, 245, 245))
    d = ImageDraw.Draw(img)
    for j, c in enumerate(colours):
        x = left + j * (w + gap)
        patch = tuple(int(v) for v in to_srgb8(np.asarray(COLOURS[c], np.float64).reshape(1, 1, 3))[0, 0, :3])
        d.rectangle([x, 8, x + 24, 32], fill=patch, outline=(0, 0, 0))
        d.text((x + 30, 14), f"{c} {COLOURS[c]}", fill=(0, 0, 0))
    for i, b in enumerate(presets):
        y = top + i * (h + gap)
        d.text((8, y + h // 2 - 6), b, fill=(0, 0, 0))
        for j, c in enumerate(colours):
            tile = Image.open(tiles[(b, c)]).convert("RGB").resize((w, h), Image.NEAREST)
            img.paste(tile, (left + j * (w + gap), y))
    img.save(out)


def main() -> int:
    from pipeline.bcsdf_presets import bcsdf_presets

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "out" / "gallery")
    ap.add_argument("--presets", default=",".join(bcsdf_presets()))
    ap.add_argument("--colours", default=",".join(COLOURS))
    ap.add_argument("--spp", type=int, default=64, help="samples per pixel of the chart's studio renders")
    ap.add_argument("--sky-spp", type=int, default=256, help="samples per pixel of the colour check's renders")
    ap.add_argument("--methods", default="fiberpath,bysdf,volpath", help="methods of the colour check")
    ap.add_argument("--tolerance", type=float, default=5.0, help="ΔE2000 a swatch may miss its colour by")
    ap.add_argument("--strict", action="store_true", help="exit 1 when a swatch misses by more than --tolerance")
    ap.add_argument("--chart-only", action="store_true", help="render the chart only (no colour check)")
    ap.add_argument("--docs", action="store_true", help="copy the chart to docs/img/material_chart.png")
    ap.add_argument("--keep", action="store_true",
                    help="reuse the artifacts and renders already in OUT (delete a method's EXRs to render it again)")
    args = ap.parse_args()
    presets = [p for p in args.presets.split(",") if p]
    colours = [c for c in args.colours.split(",") if c]
    methods = [m for m in args.methods.split(",") if m]
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows, tiles = [], {}
    for c in colours:
        col = COLOURS[c]
        base = out / f"swatch_{c}.toml"
        base.write_text(scene_text(col, presets[0], sky=False))
        yarns, fibers = out / f"yarns_{c}.zarr", out / f"fibers_{c}.zarr"
        if not (args.keep and yarns.exists() and fibers.exists()):
            loomlight("ingest", base, "-o", yarns)
            loomlight("realize", yarns, "-o", fibers)
        for b in presets:
            studio, sky = out / f"studio_{b}_{c}.toml", out / f"sky_{b}_{c}.toml"
            studio.write_text(scene_text(col, b, sky=False))
            sky.write_text(scene_text(col, b, sky=True))
            if not (args.keep and (out / f"chart_{b}_{c}.exr").exists()):
                loomlight("render", studio, "--method", "fiberpath", "--fibers", fibers, "--spp", args.spp,
                          "-o", out / f"chart_{b}_{c}.exr")
            tiles[(b, c)] = out / f"chart_{b}_{c}.png"
            if args.chart_only:
                continue
            row = {"bcsdf": b, "colour": c, "requested": list(col)}
            walk = walk_mean(sky, fibers, b, col, WALK_RAYS)
            row["walk"] = {"mean": walk, "delta_e_requested": round(delta_e(walk, col), 2)}
            for m in methods:
                # bysdf does not read the BCSDF preset: one render per colour serves every preset's row
                exr = out / (f"sky_bysdf_{c}.exr" if m == "bysdf" else f"sky_{m}_{b}_{c}.exr")
                extra = {"fiberpath": ["--fibers", fibers], "bysdf": ["--set", f"yarns={yarns}"],
                         "volpath": ["--source", "realized", "--fibers", fibers]}[m]
                if not (args.keep and exr.exists()):
                    loomlight("render", sky, "--method", m, *extra, "--spp", args.sky_spp, "-o", exr)
                mean, n = cloth_mean(exr)
                row[m] = {"mean": [round(float(v), 4) for v in mean], "pixels": n}
            for m in methods:
                row[m]["delta_e_walk"] = round(delta_e(row[m]["mean"], walk), 2)
            rows.append(row)
            print(json.dumps(row), flush=True)
    chart(tiles, presets, colours, out / "material_chart.png")
    if args.docs:
        shutil.copyfile(out / "material_chart.png", ROOT / "docs" / "img" / "material_chart.png")
    if args.chart_only:
        print(out / "material_chart.png")
        return 0
    (out / "colours.json").write_text(json.dumps({"scene": str(SCENE.relative_to(ROOT)), "sky_spp": args.sky_spp,
                                                  "rows": rows}, indent=1) + "\n")
    lines = ["| BCSDF | colour | requested | converged (ΔE00 to requested) | "
             + " | ".join(f"{m} (ΔE00 to converged)" for m in methods) + " |",
             "|---|---|---|---|" + "---|" * len(methods)]
    for r in rows:
        cells = [r["bcsdf"], r["colour"], fmt(r["requested"]),
                 f"{fmt(r['walk']['mean'])} ({r['walk']['delta_e_requested']:.1f})"]
        cells += [f"{fmt(r[m]['mean'])} ({r[m]['delta_e_walk']:.1f})" for m in methods]
        lines.append("| " + " | ".join(cells) + " |")
    (out / "colours.md").write_text("\n".join(lines) + "\n")
    print(f"{out / 'material_chart.png'}, {out / 'colours.md'}")
    missed = [f"{r['bcsdf']} {r['colour']} ({r['walk']['delta_e_requested']:.1f})" for r in rows
              if r["walk"]["delta_e_requested"] > args.tolerance]
    if missed:
        print(f"warning: ΔE2000 above {args.tolerance:g} from the requested colour: {', '.join(missed)}")
    return 1 if missed and args.strict else 0


if __name__ == "__main__":
    sys.exit(main())
