"""Table 1 runner (``loomlight evaluate --table1``): data sizes and render times, seed 000 Table 1 form.

``run_table1(scenes, procedural, realized, out_dir)`` takes the data-size rows of the full
realization against the procedural model from ``pipeline.memory_table.table1_rows(scenes)``
(imported on demand: it belongs to the procedural stage) and the render times and peak memory of
the i-th procedural and realized volpath renders for the i-th scene (``render_stats`` of the render
artifact beside each image), with the image difference between the two (they render the same
fibres); then, for the scenes after those, procedural renders alone (``unrealized``: fabrics too
large to realize), with their wall time and their peak memory against the full realization. Writes
``table1.json``, ``report.md``/``.html`` and the ``evaluation`` artifact ``evaluation.zarr``; unchanged
inputs are not recomputed unless ``force``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import LoomError
from .evaluate import METRIC_KEYS, SSIM_NOTE, check_pair, image_metrics, load_image, render_stats

# seed 000 Table 1: data size of the full realization against the procedural model, render times
TABLE1_COLUMNS = [  # (row key, header) in the order of seed 000 Table 1
    ("scene", "Scene"),
    ("full_total_bytes", "Full: total"), ("full_regular_bytes", "Full: regular"),
    ("full_hair_bytes", "Full: hair"), ("full_loop_bytes", "Full: loop"),
    ("ours_total_bytes", "Ours: total"), ("saving", "(saving)"), ("ours_regular_bytes", "Ours: regular"),
    ("ours_hair_bytes", "Ours: hair"), ("ours_loop_bytes", "Ours: loop"),
    ("procedural_time_s", "Render time (procedural)"), ("realized_time_s", "Render time (realized)"),
    ("speed_ratio", "realized / procedural time"),
    ("procedural_peak_memory_bytes", "Peak memory (procedural)"),
    ("realized_peak_memory_bytes", "Peak memory (realized)"),
    ("procedural_wall_s", "Wall time (procedural, setup included)"),
    ("peak_over_full", "Peak memory / full realization"),
]


def load_memory_table():
    """``pipeline.memory_table`` (the procedural stage's Table-1 data sizes), imported on demand."""
    import importlib

    try:
        mod = importlib.import_module("pipeline.memory_table")
    except ModuleNotFoundError as e:
        if e.name in ("pipeline.memory_table", None):
            raise LoomError(None, "--table1", "pipeline.memory_table is not installed: the data-size rows of "
                            "Table 1 come from the procedural-yarns stage, which this loomlight lacks") from None
        raise
    if not callable(getattr(mod, "table1_rows", None)):
        raise LoomError(mod.__file__, None, "pipeline.memory_table defines no table1_rows(scenes) function")
    return mod


def _table1_cell(key: str, v) -> str:
    from ..report import fmt_bytes, fmt_num, fmt_seconds

    if v is None:
        return "-"
    if key.endswith("_bytes"):
        return fmt_bytes(v)
    if key == "saving":
        return f"({float(v):.1f}x)"
    if key.endswith("_time_s"):
        return fmt_seconds(v)
    if key == "speed_ratio":
        return f"{float(v):.2f}"
    if key == "peak_over_full":
        return f"1/{1.0 / float(v):.1f}" if 0 < v < 1 else f"{float(v):.1f}x"
    if key == "procedural_wall_s":
        return fmt_seconds(v)
    return fmt_num(v) if isinstance(v, (int, float)) else str(v)


def run_table1(scenes: Sequence[str | Path], procedural: Sequence[str | Path], realized: Sequence[str | Path],
               out_dir: str | Path, force: bool = False, unrealized: Sequence[str | Path] = ()) -> Path:
    """Seed 000 Table 1 for ``scenes``: data sizes from ``pipeline.memory_table.table1_rows(scenes)``
    and the render times of the i-th procedural and realized volpath renders for the i-th scene,
    with the image difference between the two (they render the same fibres)."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from .. import report as rp
    from ..artifacts import ArtifactWriter

    scenes = [Path(s) for s in scenes]
    procedural = [Path(p) for p in procedural]
    realized = [Path(p) for p in realized]
    unrealized = [Path(p) for p in unrealized]
    out = Path(out_dir)
    if not scenes:
        raise LoomError(None, "--scene", "--table1 needs at least one --scene")
    if len(procedural) != len(realized):
        raise LoomError(None, "--procedural", f"{len(procedural)} --procedural renders but {len(realized)} --realized; "
                        "give them in pairs, one pair per --scene in order")
    if len(procedural) > len(scenes):
        raise LoomError(None, "--procedural", f"{len(procedural)} render pairs for {len(scenes)} scenes")
    if len(procedural) + len(unrealized) > len(scenes):
        raise LoomError(None, "--unrealized",
                        f"{len(procedural)} render pairs and {len(unrealized)} unrealized renders "
                        f"for {len(scenes)} scenes (the unrealized ones belong to the scenes after the pairs)")
    for p in [*scenes, *procedural, *realized, *unrealized]:
        if not p.exists():
            raise LoomError(p, None, "file not found")
    mt = load_memory_table()
    rows = [dict(r) for r in mt.table1_rows(scenes)]
    if len(rows) != len(scenes):
        raise LoomError(mt.__file__, "table1_rows", f"returned {len(rows)} rows for {len(scenes)} scenes")
    inputs: dict[str, Path] = {f"scene:{i}:{s.name}": s for i, s in enumerate(scenes)}
    times = np.full((len(scenes), 2), np.nan)
    for i, row in enumerate(rows):
        row.setdefault("scene", scenes[i].stem)
        if "saving" not in row and row.get("full_total_bytes") and row.get("ours_total_bytes"):
            row["saving"] = row["full_total_bytes"] / row["ours_total_bytes"]
        if len(procedural) <= i < len(procedural) + len(unrealized):
            uu = unrealized[i - len(procedural)]
            load_image(uu)  # an image, readable
            su = render_stats(uu)
            inputs[f"unrealized:{i}"] = uu
            if "render_artifact" in su:
                inputs[f"unrealized_render:{i}"] = Path(su["render_artifact"])
            row["procedural_time_s"] = su.get("time_s")
            row["procedural_wall_s"] = su.get("wall_time_s")
            row["procedural_peak_memory_bytes"] = su.get("peak_memory_bytes")
            if su.get("peak_memory_bytes") and row.get("full_total_bytes"):
                row["peak_over_full"] = su["peak_memory_bytes"] / row["full_total_bytes"]
            times[i, 0] = row["procedural_time_s"] or np.nan
            continue
        if i >= len(procedural):
            continue
        pp, rr = procedural[i], realized[i]
        sp, sr = render_stats(pp), render_stats(rr)
        inputs[f"procedural:{i}"] = pp
        inputs[f"realized:{i}"] = rr
        for k, st in (("procedural", sp), ("realized", sr)):
            if "render_artifact" in st:
                inputs[f"{k}_render:{i}"] = Path(st["render_artifact"])
        a, b = load_image(pp), load_image(rr)
        check_pair(rr, b, pp, a)
        agree = image_metrics(a, b)
        row["procedural_time_s"] = sp.get("time_s")  # render time, compilation excluded
        row["realized_time_s"] = sr.get("time_s")
        if row["procedural_time_s"] and row["realized_time_s"]:
            row["speed_ratio"] = row["realized_time_s"] / row["procedural_time_s"]
            times[i] = [row["procedural_time_s"], row["realized_time_s"]]
        row["procedural_peak_memory_bytes"] = sp.get("peak_memory_bytes")
        row["realized_peak_memory_bytes"] = sr.get("peak_memory_bytes")
        if sp.get("peak_memory_bytes") and row.get("full_total_bytes"):
            row["peak_over_full"] = sp["peak_memory_bytes"] / row["full_total_bytes"]
        row["procedural_vs_realized"] = {k: agree[k] for k in METRIC_KEYS}
    from ..artifacts import jsonable

    rows = jsonable(rows)
    writer = ArtifactWriter(out / "evaluation.zarr", kind="evaluation", stage="evaluate",
                            params={"mode": "table1", "rows": rows}, inputs=inputs, started=t_start)
    md = out / "report.md"
    if not force and writer.up_to_date() and md.exists() and (out / "table1.json").exists():
        return md
    rp.write_text(out / "table1.json", json.dumps(rows, indent=2) + "\n")
    keys = [k for k, _ in TABLE1_COLUMNS if any(r.get(k) is not None for r in rows)]
    extra = [k for r in rows for k in r if k not in dict(TABLE1_COLUMNS) and k != "procedural_vs_realized"]
    extra = list(dict.fromkeys(extra))
    headers = [dict(TABLE1_COLUMNS)[k] for k in keys] + extra
    rep = rp.Report("Data size and render time (Luan, Zhao, Bala 2017 Table 1 form)")
    rep.paragraph("Data size of the fully realized fibre model (regular, hair and loop fibres) against the "
                  "procedural model the renderer reads on the fly (Luan, Zhao, Bala 2017 Table 1), and the wall time "
                  "of the "
                  "volumetric path tracer on the procedural model against the same tracer on the fully realized "
                  "fibres. Luan, Zhao, Bala 2017 (§6) report that the two run at approximately the same speed.")
    rep.table(headers, [[_table1_cell(k, r.get(k)) for k in keys + extra] for r in rows])
    agree_rows = [[r["scene"]] + [rp.fmt_num(r["procedural_vs_realized"][k]) for k in METRIC_KEYS]
                  for r in rows if "procedural_vs_realized" in r]
    if agree_rows:
        rep.heading("Procedural against realized renders")
        rep.paragraph("Both renders trace the same fibres, so their images agree up to Monte Carlo noise; "
                      "metrics of the procedural render with the realized one as reference. " + SSIM_NOTE)
        rep.table(["scene", "RMSE", "relMSE", "SSIM", "mean ΔE00"], agree_rows)
    md, _ = rep.write(out)
    with writer as w:
        w.write("render_time_s", times, dimension_names=("scene", "procedural_realized"))
        w.summary.update(kind="evaluation", mode="table1", rows=rows, metrics=[k for k, _ in TABLE1_COLUMNS])
    return md
