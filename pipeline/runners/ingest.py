"""Ingest runner: a curve file, WIF draft or scene → validated, splined yarn curves (``yarns`` artifact).

``run_ingest`` reads the input (``curves_from_input``: curve files through ``pipeline.io``, WIF drafts
and scene generators through ``pipeline.generators``), checks the curves (``validate_curves``), gives
every curve a yarn type, radius and colour (``curve_colors``: the scene's group colour, else the
draft's thread colour, else the yarn type's), splines them (``stages.ingest.spline_process``) and
publishes the ``yarns`` artifact (its summary's ``thread_colors`` lists the colours per group).
"""
from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np

from ..artifacts import FILE, ArtifactWriter
from ..curveset import GROUPS, CurveSet
from ..errors import LoomError
from ..limits import MAX_COORD, MAX_LENGTH, coordinate_problem, first_bad_row
from ..memory import Estimate, budget as memory_budget
from ..progress import info, warn
from ..scene import load_scene
from ..thread_colors import FROM_DRAFT, FROM_SCENE, FROM_TYPE, describe as describe_colors

# the colour the yarns inspector draws a yarn whose colour is its yarn type's (the preset albedo is
# resolved later, by tables / realize); never rendered
DEFAULT_COLORS = {"warp": (0.80, 0.78, 0.72), "weft": (0.25, 0.35, 0.60), "knit": (0.70, 0.25, 0.22),
                  "other": (0.6, 0.6, 0.6)}


def part_curves(part, radius: float | None, scale: float | None) -> tuple[CurveSet, Path | None]:
    """(CurveSet, its source file or None) of one fabric of a scene (``pipeline.scene.FabricPart``), where its
    source puts it (``placed`` moves it)."""
    from ..scene import merged_yarn_type

    fab = part.fabric
    if fab["source"] == "generator":
        from ..generators import generate

        gen = fab["generator"]
        r = gen.get("yarn_radius") or merged_yarn_type(part.yarns, "warp").get("radius") or radius
        return generate(gen, r), None
    src = Path(fab["path"])
    if fab["source"] == "wif":
        from ..generators import from_wif

        return from_wif(src, scale=fab.get("scale", scale or 1.0), crimp=fab.get("crimp", 1.0),
                        max_threads=fab.get("max_threads"), repeat=fab.get("repeat")), src
    from ..io import read_curves

    return _scaled(read_curves(src), fab.get("scale", scale), src), src


def placed(cs: CurveSet, M: np.ndarray, file: Path, key: str) -> CurveSet:
    """The curves moved by the rigid placement ``M`` (3 x 4, ``pipeline.scene.placement``), refusing a point
    moved beyond the coordinate limits (``key``: the transform's key)."""
    R, t = M[:, :3], M[:, 3]
    out = []
    for c, p in enumerate(cs.points):
        q = np.asarray(p, np.float64) @ R.T + t
        k = first_bad_row(q)
        if k >= 0:
            raise LoomError(file, key, f"moves curve {c}, point {k} to {q[k].tolist()}, beyond +-{MAX_COORD:g} "
                            "scene units")
        out.append(q)
    cs.points = out
    return cs


def draped(cs: CurveSet, spec: dict, file: Path, key: str) -> CurveSet:
    """The curves laid on the surface of a ``drape`` table (``key``), its z along the surface's normal: their
    (x, y) about the centre of their box along a cylinder or over a ball (``stages.tile.base_surfaces.drape``),
    or from their box's corner through an OBJ mesh's uv chart (``stages.tile.base_surfaces.chart_points``). A
    point moved beyond the coordinate limits, or outside the OBJ's uv chart, is refused at ``key``."""
    from stages.tile import base_surfaces as bs

    lo = np.min([np.min(p, axis=0) for p in cs.points], axis=0)
    hi = np.max([np.max(p, axis=0) for p in cs.points], axis=0)
    size = float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-12))
    n = [len(p) for p in cs.points]
    flat = np.concatenate([np.asarray(p, np.float64) for p in cs.points])
    if spec["surface"] == "obj":
        moved = _on_obj(flat, lo, hi, spec, file, key)
    else:
        R = float(spec["radius"])
        if spec["surface"] == "cylinder":
            def surface(x, y):
                return bs.cylinder_points(x, y, R)
        else:
            def surface(x, y):
                return bs.sphere_drape_points(x, y, size, R, int(spec["folds"]), float(spec["fold_amplitude"]))
        centre = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.0])
        moved = bs.drape(flat - centre, surface, size)
    k = first_bad_row(moved)
    if k >= 0:
        raise LoomError(file, key, f"moves control point {k} to {moved[k].tolist()}, beyond +-{MAX_COORD:g} "
                        "scene units")
    cs.points = list(np.split(moved, np.cumsum(n)[:-1]))
    return cs


def _on_obj(flat: np.ndarray, lo: np.ndarray, hi: np.ndarray, spec: dict, file: Path, key: str) -> np.ndarray:
    """``draped``'s OBJ surface: u = (x - lo_x) / uv_size[0], v = (y - lo_y) / uv_size[1] (default uv_size: the
    box), the point on the scaled mesh there lifted z along its normal."""
    from stages.tile import base_surfaces as bs

    from ..io.obj_mesh import read_obj_mesh

    mesh = read_obj_mesh(spec["file"], file, uv_for="a drape reads the fabric's place from them",
                         place=f"{key}.file", faces_for="a drape needs a surface")
    uv_size = np.asarray(spec.get("uv_size", np.maximum(hi[:2] - lo[:2], 1e-12)), np.float64)
    chart = bs.uv_chart(mesh.V * float(spec.get("scale", 1.0)), mesh.UV, mesh.F)
    u, v = (flat[:, 0] - lo[0]) / uv_size[0], (flat[:, 1] - lo[1]) / uv_size[1]
    moved, outside = bs.chart_points(chart, u, v, flat[:, 2])
    if outside.any():
        k = int(np.argmax(outside))
        raise LoomError(file, key, f"control point {k} falls at uv ({u[k]:.4g}, {v[k]:.4g}), on no triangle of "
                        f"{Path(spec['file']).name} (its uv chart spans {chart.lo.round(4).tolist()} to "
                        f"{(chart.lo + chart.G / chart.inv).round(4).tolist()}; {int(outside.sum())} points "
                        "outside): give a larger uv_size, or a mesh whose uv covers the fabric")
    return moved


def scene_curves(scene, radius: float | None, scale: float | None,
                 merge_duplicates: bool = True) -> tuple[CurveSet, np.ndarray, dict]:
    """(CurveSet of every fabric of the scene, placed and in order; (C,) the fabric of each curve; the source
    files by their scene key). Of several fabrics, each is validated before it is placed and merged, so that a
    bad curve is named by its own file (or the scene, for a generator) and its index there."""
    sets, files = [], {}
    for part in scene.parts:
        cs, src = part_curves(part, radius, scale)
        if src is not None:
            files[part.key] = src
        if scene.several:
            cs = validate_curves(cs, src or scene.path, merge_duplicates and part.fabric.get("merge_duplicates", True))
        if part.drape is not None:
            cs = draped(cs, part.drape, scene.path, part.key.replace(".fabric", ".drape"))
        if part.matrix is not None:
            cs = placed(cs, part.matrix, scene.path, part.key.replace(".fabric", ".transform"))
        sets.append(cs)
    if len(sets) == 1:
        return sets[0], np.zeros(len(sets[0].points), np.int64), files
    radii = [cs.point_radius if cs.point_radius is not None else [None] * len(cs.points) for cs in sets]
    no_radii = all(cs.point_radius is None for cs in sets)
    merged = CurveSet(points=[p for cs in sets for p in cs.points], closed=[c for cs in sets for c in cs.closed],
                      group=[g for cs in sets for g in cs.group],
                      point_radius=None if no_radii else [r for rs in radii for r in rs],
                      color=[c for cs in sets for c in cs.color],
                      source_format="+".join(dict.fromkeys(cs.source_format for cs in sets)))
    part_of = np.concatenate([np.full(len(cs.points), i) for i, cs in enumerate(sets)])
    return merged, part_of, files


def curves_from_input(path: Path, radius: float | None, scale: float | None, merge_duplicates: bool = True):
    """(CurveSet, the fabric of each curve (index into the scene's parts; 0 without a scene), scene or None,
    extra input files by name) for any INPUT the ingest command takes."""
    if path.suffix.lower() == ".toml":
        scene = load_scene(path)
        cs, part_of, files = scene_curves(scene, radius, scale, merge_duplicates)
        return cs, part_of, scene, files
    if path.suffix.lower() == ".wif":
        from ..generators import from_wif

        cs = from_wif(path, scale=scale or 1.0, crimp=1.0, max_threads=None, repeat=None)
    else:
        from ..io import read_curves

        cs = _scaled(read_curves(path), scale, path)
    return cs, np.zeros(len(cs.points), np.int64), None, {}


def _scaled(cs: CurveSet, s: float | None, file: Path) -> CurveSet:
    """Coordinates and radii times ``s`` (when given), refusing a product beyond the limits."""
    if not s:
        return cs
    for c, p in enumerate(cs.points):
        k = first_bad_row(np.asarray(p, np.float64) * s)
        if k >= 0:
            raise LoomError(file, f"curve {c}, point {k}", f"scaled by {s:g}, coordinate {np.asarray(p)[k].tolist()} "
                            f"goes beyond +-{MAX_COORD:g} scene units")
    cs.points = [p * s for p in cs.points]
    if cs.point_radius is not None:
        cs.point_radius = [r * s for r in cs.point_radius]
    return cs


def validate_curves(cs: CurveSet, file: Path, merge_duplicates: bool) -> CurveSet:
    """NaN/inf, fewer than 2 points, repeated consecutive points (merged with a warning, or refused)."""
    if not cs.points:
        raise LoomError(file, None, "no curves")
    pts_out, rad_out = [], []
    merged_total = 0
    for c, pts in enumerate(cs.points):
        if np.ndim(pts) != 2 or np.shape(pts)[1] != 3:
            raise LoomError(file, f"curve {c}", f"expected (n, 3) control points, got shape {np.shape(pts)}")
        k = first_bad_row(pts)
        if k >= 0:
            raise LoomError(file, f"curve {c}, point {k}", coordinate_problem(np.asarray(pts, np.float64)[k].tolist()))
        pts = np.asarray(pts, dtype=np.float32)
        rad = None if cs.point_radius is None or cs.point_radius[c] is None \
            else np.asarray(cs.point_radius[c], dtype=np.float32)
        if rad is not None and (~np.isfinite(rad) | (rad <= 0) | (rad > MAX_LENGTH)).any():
            k = int(np.argmax(~np.isfinite(rad) | (rad <= 0) | (rad > MAX_LENGTH)))
            raise LoomError(file, f"curve {c}, point {k}", f"radius must be positive and at most {MAX_LENGTH:g}, "
                            f"got {rad[k]}")
        if len(pts) < 2:
            raise LoomError(file, f"curve {c}", f"a curve needs at least 2 points, got {len(pts)}")
        same = np.all(pts[1:] == pts[:-1], axis=1)
        closing_dup = bool(cs.closed[c] and len(pts) > 1 and np.all(pts[0] == pts[-1]))
        if same.any() or closing_dup:
            k = int(np.argmax(same)) + 1 if same.any() else len(pts) - 1
            if not merge_duplicates:
                raise LoomError(file, f"curve {c}, point {k}", "repeated consecutive control point "
                                "(re-run without --refuse-duplicates to merge them)")
            keep = np.concatenate([[True], ~same])
            if closing_dup:
                keep[-1] = False
            merged_total += int((~keep).sum())
            pts = pts[keep]
            rad = rad[keep] if rad is not None else None
        need = 3 if cs.closed[c] else 2
        if len(pts) < need:
            raise LoomError(file, f"curve {c}", f"fewer than {need} distinct points after merging repeats")
        pts_out.append(pts)
        rad_out.append(rad)
    if merged_total:
        warn(f"{file}: merged {merged_total} repeated consecutive control point(s)")
    cs.points = pts_out
    cs.point_radius = None if cs.point_radius is None else rad_out
    return cs


def curve_colors(cs: CurveSet, types: list, yarn_type: np.ndarray):
    """(color (C, 3) float32 linear RGB, color_source (C,) int8) of every curve, by precedence: the
    scene's colour of its yarn group (``yarns.<group>.color``, ``yarns.default`` merged in) wins over
    the input file's thread colour (a WIF draft's), which wins over the yarn type's (its preset's
    albedo, resolved by tables / realize: ``color`` then holds the group colour the inspector draws).
    This is the one place the precedence is decided (``pipeline.thread_colors``)."""
    n = len(cs.points)
    color = np.empty((n, 3), dtype=np.float32)
    source = np.empty(n, dtype=np.int8)
    for c in range(n):
        scene_col = types[yarn_type[c]].get("color")
        if scene_col is not None:
            color[c], source[c] = scene_col, FROM_SCENE
        elif cs.color[c] is not None:
            color[c], source[c] = cs.color[c], FROM_DRAFT
        else:
            color[c], source[c] = DEFAULT_COLORS[cs.group[c]], FROM_TYPE
    return color, source


def _estimate_radius(cs: CurveSet) -> float:
    seg = np.concatenate([np.linalg.norm(np.diff(p, axis=0), axis=1) for p in cs.points])
    return float(0.5 * np.median(seg)) if len(seg) else 1.0


# ------------------------------------------------------------------------------------------------ memory
POINT_BYTES = 140        # per control point: curve lists, float32/float64 copies, tangents, segments, grid items
FRAME_BYTES = 40         # per frame sample (--frame-samples per segment): arc length, normal, twist
FILE_BYTES = 8           # reading a curve file: its bytes, decoded, a few times over
WIF_LINE_BYTES = 250     # a parsed WIF line: key, value and line number in the section dictionaries


def curves_estimate(points: float, frame_samples: int, what: str = "loomlight ingest") -> Estimate:
    """Splining ``points`` control points: frames, segment grid and the arrays of the yarns artifact."""
    return Estimate(what).add("yarn curves", points * (POINT_BYTES + FRAME_BYTES * frame_samples),
                              f"{int(points):,} control points")


def woven_points(ends: float, picks: float, samples: int) -> float:
    """Control points of a woven fabric (stages.core.curves.woven: (K - 1) s + 2 (s // 2) + 1 per yarn)."""
    def per(k):
        return (k - 1) * samples + 2 * (samples // 2) + 1
    return ends * per(picks) + picks * per(ends)


def _wif_counts(path: Path) -> dict:
    """Declared (else largest used) ends, picks, shafts and treadles of a WIF draft, read from its section
    dictionaries before any matrix is built; values the reader will refuse count as 0."""
    from ..io.wif import parse_sections

    s = parse_sections(path)

    def declared(sec, key):
        v = s.get(sec, {}).get(key, (None, None))[0]
        try:
            return max(0, int(str(v).replace(" ", "")))
        except ValueError:
            return 0

    def used(sec):
        keys, vals = [0], [0]
        for k, (v, _) in s.get(sec, {}).items():
            if k.isdigit():
                keys.append(int(k))
                vals += [int(x) for x in re.findall(r"\d+", v or "")]
        return max(keys), max(vals)

    th_key, th_val = used("threading")
    pick_key, lift_val = used("liftplan" if "liftplan" in s else "treadling")
    tu_key, tu_val = used("tieup")
    return {"ends": max(declared("warp", "threads"), th_key), "picks": max(declared("weft", "threads"), pick_key),
            "shafts": max(declared("weaving", "shafts"), th_val, tu_val, lift_val if "liftplan" in s else 0),
            "treadles": max(declared("weaving", "treadles"), tu_key, 0 if "liftplan" in s else lift_val)}


def wif_estimate(path: Path, frame_samples: int, repeat=None, max_threads=None, samples: int = 6) -> Estimate:
    """A WIF draft's ingest: the parsed sections, the threading, lift and interlacement matrices (bool and
    the int64 products of pipeline.io.wif / stages.ingest.weave), per-thread colours, then the woven curves
    of the repeated, cropped draft."""
    est = Estimate("loomlight ingest")
    est.add("WIF sections", WIF_LINE_BYTES * path.stat().st_size / 4, path.name)
    n = _wif_counts(path)
    E, P, S, T = (float(n[k]) for k in ("ends", "picks", "shafts", "treadles"))
    est.add("draft matrices", 9 * (E * S + P * S + P * T + T * S + E * P) + 8 * (E + P),
            f"{int(E):,} ends x {int(P):,} picks, {int(S):,} shafts, {int(T):,} treadles")
    rx, ry = (int(x) for x in repeat) if repeat is not None else (1, 1)
    E, P = E * max(rx, 1), P * max(ry, 1)
    if max_threads is not None and int(max_threads) >= 1:
        E, P = min(E, int(max_threads)), min(P, int(max_threads))
    est.add("repeated draft", 9 * E * P)
    return est.extend(curves_estimate(woven_points(E, P, samples), frame_samples))


def input_estimate(path: Path, frame_samples: int) -> Estimate:
    """Memory of reading and splining an ingest input, from what it declares before anything is built: a
    generator's ends, picks and samples, a WIF draft's thread, shaft and treadle counts, a curve file's size."""
    if path.suffix.lower() == ".wif":
        return wif_estimate(path, frame_samples)
    if path.suffix.lower() != ".toml":
        return Estimate("loomlight ingest").add("reading", FILE_BYTES * path.stat().st_size, path.name)
    est = Estimate("loomlight ingest")
    for part in load_scene(path).parts:
        est.extend(fabric_estimate(part.fabric, frame_samples))
    return est


def fabric_estimate(fab: dict, frame_samples: int) -> Estimate:
    """``input_estimate`` of one fabric source table of a scene."""
    if fab["source"] == "wif":
        return wif_estimate(Path(fab["path"]), frame_samples, fab.get("repeat"), fab.get("max_threads"))
    if fab["source"] != "generator":
        return input_estimate(Path(fab["path"]), frame_samples)
    gen = fab["generator"]
    ends, picks = float(gen.get("ends", 16)), float(gen.get("picks", 16))
    if gen.get("kind") == "knit":
        s = int(gen.get("samples_per_cell", 16))
        pts = picks * (ends * s + 1)
    else:
        s = int(gen.get("samples_per_cell", 6))
        pts = woven_points(ends, picks, s)
    est = Estimate("loomlight ingest").add("generated curves", 64 * pts,
                                           f"{gen.get('kind')} {int(ends):,} x {int(picks):,}")
    return est.extend(curves_estimate(pts, frame_samples))


def _identity(scene, input_path: Path, scale) -> dict:
    """What the artifact is made of (``pipeline.scene.ingest_identity``), for render to compare its scene with."""
    from ..scene import file_identity, ingest_identity

    if scene is None:
        return file_identity(input_path, scale)
    ident = ingest_identity(scene)
    fabrics = ident["fabric"].get("fabrics", [ident["fabric"]])
    for part, fab in zip(scene.parts, fabrics):
        if scale and part.fabric["source"] != "generator" and "scale" not in part.fabric:
            fab["scale"] = scale  # --scale applies where the scene states none
    return ident


def run_ingest(input_path: Path, out: Path, radius: float | None = None, scale: float | None = None,
               merge_duplicates: bool = True, force: bool = False, write: Path | None = None,
               frame_samples: int = 4, budget=None) -> dict:
    """Ingest (or skip when up to date); ``budget`` (``pipeline.memory.budget``): refuse an input whose
    estimated peak memory exceeds it, before it is read (``input_estimate``) and again, from its control
    points, before it is splined."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.ingest.spline_process import process_curves

    input_path = Path(input_path)
    if not input_path.exists():
        raise LoomError(input_path, None, "input file not found")
    limit = budget or memory_budget()
    input_estimate(input_path, frame_samples).check(limit, input_path)
    cs, part_of, scene, extra_inputs = curves_from_input(input_path, radius, scale, merge_duplicates)
    params = {"input": str(input_path), "radius": radius, "scale": scale, "merge_duplicates": merge_duplicates,
              "frame_samples": frame_samples}
    writer = ArtifactWriter(out, kind="yarns", stage="ingest", params=params,
                            inputs={name: (p, FILE) for name, p in {"input": input_path, **extra_inputs}.items()},
                            started=t_start)
    if writer.up_to_date() and not force and write is None:
        (Path(out) / "zarr.json").touch()
        info(f"{out} is up to date (same inputs and parameters); use --force to rebuild")
        return {"skipped": True}
    src_file = extra_inputs.get("fabric", input_path)
    curves_estimate(sum(len(p) for p in cs.points), frame_samples).check(limit, src_file)
    # the scene's fabric.merge_duplicates = false refuses repeats as --refuse-duplicates does; several fabrics were
    # validated each in its own file, and are again here: placing them can round neighbouring points together
    merge = merge_duplicates and (scene is None or scene.fabric.get("merge_duplicates", True))
    cs = validate_curves(cs, src_file, merge)
    if write is not None:
        from ..io import write_curves
        from ..outputs import check_not_input

        check_not_input(write, "--write", extra_inputs.values())  # a scene's curve file (fabric.path)
        write_curves(write, cs)
        info(f"wrote {write}")

    # yarn types per (fabric, group) (scene; pipeline.scene: type = fabric * 4 + group), radii, colours
    ncurve = len(cs.points)
    group_idx = np.array([GROUPS.index(g) for g in cs.group], dtype=np.int8)
    labels = scene.type_labels() if scene is not None else list(GROUPS)
    types = [{"group": GROUPS[k % len(GROUPS)], **(scene.yarn_type(label) if scene is not None else {})}
             for k, label in enumerate(labels)]
    yarn_type = (part_of * len(GROUPS) + group_idx).astype(np.int16)
    rad = np.empty(ncurve)
    fabrics = [p.fabric for p in scene.parts] if scene is not None else [{}]
    estimated = False
    for c in range(ncurve):
        fab = fabrics[part_of[c]]
        if cs.point_radius is not None and cs.point_radius[c] is not None:
            rad[c] = float(np.mean(cs.point_radius[c]))
        elif types[yarn_type[c]].get("radius"):
            rad[c] = types[yarn_type[c]]["radius"]
        elif fab.get("source") == "generator" and fab["generator"].get("yarn_radius"):
            rad[c] = fab["generator"]["yarn_radius"]
        elif radius or fab.get("radius"):
            rad[c] = radius or fab.get("radius")
        else:
            estimated = True
            rad[c] = np.nan
    if estimated:
        est = _estimate_radius(cs)
        rad[np.isnan(rad)] = est
        warn(f"{input_path}: no yarn radius given (--radius, fabric.radius or yarns.<group>.radius); "
             f"using half the median control-point spacing, {est:.6g}")
    color, color_source = curve_colors(cs, types, yarn_type)

    points = np.concatenate(cs.points).astype(np.float32)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in cs.points])]).astype(np.int64)
    closed = np.array(cs.closed, dtype=bool)
    # a placed fabric's frames start from its own up axis (the rotated z), so that they turn with it
    axes = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    rot = [axes if p.matrix is None else axes @ p.matrix[:, :3].T for p in scene.parts] if scene is not None \
        else [axes]
    proc = process_curves(points.astype(np.float64), offsets, closed, rad, frame_samples=frame_samples,
                          frame_axes=np.stack([rot[k] for k in part_of]))

    with writer as w:
        w.write("points", points, dimension_names=("point", "xyz"))
        w.write("curve_offsets", offsets)
        w.write("closed", closed)
        w.write("radius", rad.astype(np.float64))
        w.write("group", group_idx)
        w.write("color", color)
        w.write("color_source", color_source)
        w.write("yarn_type", yarn_type)
        for name in ("tangents", "seg_curve", "seg_length", "seg_arclen", "curve_length", "frame_s",
                     "frame_offsets", "frame_normal", "frame_twist", "delta", "grid_lo", "grid_cell",
                     "grid_dims", "grid_cell_start", "grid_items", "grid_pad"):
            w.write(name, proc[name])
        lo = points.min(axis=0)
        hi = points.max(axis=0)
        w.summary.update({
            "kind": "yarns", "curves": int(ncurve), "closed_curves": int(closed.sum()),
            "control_points": int(len(points)), "bounds": [lo.tolist(), hi.tolist()],
            "groups": [labels[k] for k in sorted(set(yarn_type.tolist()))],
            "yarn_types": types, "total_length": float(proc["curve_length"].sum()),
            "source_format": cs.source_format, "curve_type": cs.curve_type,
            "radius_range": [float(rad.min()), float(rad.max())],
            "thread_colors": describe_colors(labels, yarn_type, color, color_source),
            "delta_max": float(proc["delta"].max()),
            "grid": {"dims": proc["grid_dims"].tolist(), "cell": float(proc["grid_cell"][0]),
                     "items": int(len(proc["grid_items"]))},
            "scene": str(input_path) if scene is not None else None,
            "ingest_identity": {**_identity(scene, input_path, scale),
                                "groups": [labels[k] for k in sorted(set(yarn_type.tolist()))]},
        })
    return {"skipped": False, "curves": ncurve}
