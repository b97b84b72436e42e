"""A comparison's btf pictures beside the fibres' (``make btf-through``, after ``make compare``).

Reads a convergence comparison's directory (``loomlight evaluate --convergence data/compare/knit_btf.toml``): its
converged reference and each named method's render at its largest budget, and draws them side by side on the
reference's exposure (sRGB), each titled with its mean per channel over the cloth pixels (the reference's alpha
> 0.5) as a fraction of the reference's and its per-pixel error (``stages.evaluate.convergence.relative_error``,
the reference's noise not subtracted). Writes ``OUT/NAME`` (``--png``, default btf_knit_through.png); ``--docs``
copies it to docs/img/.

    .venv/bin/python scripts/btf_planes.py out/compare/knit_btf -o out/btf \\
        --method btf_tabulated "hemisphere, top face" --method btf_through "sphere, relief" [--docs]
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def srgb(x, scale):
    y = np.clip(np.asarray(x, float) / scale, 0.0, 1.0)
    return np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1 / 2.4) - 0.055)


def main(argv=None) -> int:
    from pipeline.images import read_exr
    from stages.evaluate.convergence import cloth_mask, relative_error

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("compare_dir", type=Path)
    ap.add_argument("-o", "--out", type=Path, required=True)
    ap.add_argument("--method", nargs=2, action="append", metavar=("NAME", "LABEL"), required=True)
    ap.add_argument("--png", default="btf_knit_through.png")
    ap.add_argument("--docs", action="store_true")
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref, ch = read_exr(a.compare_dir / "reference" / "reference.exr")
    ref = ref.astype(np.float64)
    mask = cloth_mask(ch["A"])
    scale = float(np.percentile(ref[mask], 99))
    panels = [("fiberpath, converged", ref, None)]
    for name, label in a.method:
        renders = sorted((a.compare_dir / "renders" / name).glob("spp*.exr"))
        if not renders:
            print(f"error: {a.compare_dir / 'renders' / name}: no renders (run make compare)", file=sys.stderr)
            return 2
        img = read_exr(renders[-1])[0].astype(np.float64)
        err = relative_error(img, ref, np.zeros_like(ref), ch["A"], 2)   # the reference's noise not subtracted
        panels.append((f"{name}: {label}", img, err))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.9), layout="constrained")
    for ax, (title, img, err) in zip(np.atleast_1d(axes), panels):
        ax.imshow(srgb(img, scale), interpolation="nearest")
        ratio = img[mask].mean(axis=0) / ref[mask].mean(axis=0)
        sub = "mean " + " / ".join(f"{r:.2f}" for r in ratio)
        if err is not None:
            sub += f", error {np.sqrt(err.raw_e2):.3f}"
        ax.set_title(f"{title}\n{sub}", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"comparison {a.compare_dir.name}: btf against the fibres (each at its largest budget)", fontsize=10)
    a.out.mkdir(parents=True, exist_ok=True)
    png = a.out / a.png
    fig.savefig(png, dpi=80)
    print(png)
    if a.docs:
        shutil.copy(png, ROOT / "docs" / "img" / png.name)
        print(ROOT / "docs" / "img" / png.name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
