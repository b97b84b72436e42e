"""The README's picture, docs/img/methods.png, from ``make demo-full``'s own renders.

    .venv/bin/python scripts/readme_figure.py [--demo out/demo-full] [-o docs/img/methods.png]

Two rows, because no one fabric takes all four methods: the demo swatch (``fiberpath``, procedural
``volpath``, ``bysdf`` with the demo's fit) and the draped damask (``fiberpath``, ``prt``, ``btf``), each
tile the render's sRGB PNG, labelled. ``make demo-full`` renders all but the swatch's ``bysdf``, which this
script renders from the demo's yarns and fit (240x180, 16 spp) when it is missing. Exits 1 naming a missing
render (run ``make demo-full`` first).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROWS = (("demo swatch", (("fiberpath (reference)", "fiberpath.png"), ("volpath (procedural)", "volpath.png"),
                         ("bysdf (fitted)", "bysdf.png"))),
        ("draped damask", (("fiberpath (reference)", "damask.png"), ("prt", "damask_prt.png"),
                           ("btf", "damask_btf.png"))))
LEFT, TOP, GAP = 0, 22, 6


def main() -> int:
    from PIL import Image, ImageDraw

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", type=Path, default=ROOT / "out" / "demo-full")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "docs" / "img" / "methods.png")
    args = ap.parse_args()
    if not (args.demo / "bysdf.png").exists() and (args.demo / "bysdf_fit.toml").exists():
        subprocess.run([str(Path(sys.executable).parent / "loomlight"), "render", str(ROOT / "data/scenes/demo.toml"),
                        "--method", "bysdf", "--set", f"yarns={args.demo / 'yarns.zarr'}",
                        "--set", f"params={args.demo / 'bysdf_fit.toml'}", "--spp", "16", "--width", "240",
                        "--height", "180", "-o", str(args.demo / "bysdf.exr")], check=True)
    missing = [str(args.demo / f) for _, row in ROWS for _, f in row if not (args.demo / f).exists()]
    if missing:
        print(f"readme_figure: no {', '.join(missing)}; run make demo-full first", file=sys.stderr)
        return 1
    tiles = [[Image.open(args.demo / f).convert("RGB") for _, f in row] for _, row in ROWS]
    w, h = tiles[0][0].size
    img = Image.new("RGB", (LEFT + 3 * (w + GAP), len(ROWS) * (h + TOP + GAP)), (255, 255, 255))
    d = ImageDraw.Draw(img)
    for i, (name, row) in enumerate(ROWS):
        y = i * (h + TOP + GAP) + TOP
        for j, ((label, _), tile) in enumerate(zip(row, tiles[i])):
            x = LEFT + j * (w + GAP)
            img.paste(tile.resize((w, h)), (x, y))
            d.text((x + 4, y - TOP + 5), f"{name}: {label}" if j == 0 else label, fill=(0, 0, 0))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    img.save(args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
