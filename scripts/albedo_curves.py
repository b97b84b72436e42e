"""Write data/bcsdf/albedo_curves.json: the albedo curve (pipeline/dye.py) of every bundled BCSDF preset on
every bundled yarn preset, and bysdf's colour curve (pipeline/renderers/bysdf.py) of every bundled yarn
preset with its default material, so that renders of bundled data never measure one at run time.

    .venv/bin/python scripts/albedo_curves.py [--check]

``--check`` measures nothing: it exits 1 when a bundled pair has no curve in the file (after a change to
a preset, to the measurement or to CURVE_VERSION). Run by ``make albedo-curves``: 5-10 s per
pair on 2 cores, 45 pairs, and ~10 s per bysdf curve, 9 yarns.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> int:
    from pipeline import dye
    from pipeline.bcsdf_presets import bcsdf_presets, load_bcsdf_preset
    from pipeline.presets import list_presets, resolve_yarn_types
    from pipeline.renderers import bysdf

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only say whether every bundled pair has its curve")
    args = ap.parse_args()
    old = dye._read(dye.BUNDLED_CURVES)
    new, missing = {}, []

    def keep_or_measure(key: str, about: dict, measure) -> None:
        """Keep the bundled curve of ``key``, else (unless --check) measure it and write the file at once."""
        if key in old:
            new[key] = old[key]
            return
        what = f"{about.get('bcsdf', about.get('method'))} on {about['yarn']}"
        missing.append(what)
        if args.check:
            return
        t0 = time.perf_counter()
        c = measure()
        new[key] = {"x": c.x.tolist(), "albedo": c.albedo.tolist(), "about": about}
        print(f"{what:24s} A(0) {c.albedo[0]:.4f}  A(1) {c.albedo[-1]:.4f}  {time.perf_counter() - t0:.1f} s",
              flush=True)
        dye.write_curves(dye.BUNDLED_CURVES, {**old, **new})

    for y in list_presets():
        preset = resolve_yarn_types([{"preset": y}], [0.0])[0]
        geo = dye.unit_geometry(preset)
        for b in bcsdf_presets():
            p, refl = load_bcsdf_preset(b), dye.preset_reflection(b)
            keep_or_measure(dye.curve_key(p, refl, geo), {"bcsdf": b, "yarn": y},
                            lambda p=p, refl=refl, geo=geo: dye.measure_curve(p, refl, geo))
        material, model = dict(bysdf.MATERIAL_DEFAULTS), bysdf.YarnModel()
        keep_or_measure(bysdf.colour_curve_key(material, preset, model), {"method": "bysdf", "yarn": y},
                        lambda m=material, g=preset, k=model: bysdf.measure_colour_curve(m, g, k))
    if args.check:
        if missing:
            print(f"{dye.BUNDLED_CURVES}: no curve for {', '.join(missing)}; run make albedo-curves", file=sys.stderr)
            return 1
        return 0
    dye.write_curves(dye.BUNDLED_CURVES, new)      # drops curves of presets that changed
    print(f"{dye.BUNDLED_CURVES}: {len(new)} curves ({len(missing)} measured)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
