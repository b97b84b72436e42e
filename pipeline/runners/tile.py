"""Tile runner: exemplars, block map and shell mesh from a tiling configuration (TOML) (``tiling`` artifact).

Configuration (``schemas/tile-config.schema.json``; relative paths against the file's directory):
  scene            scene file with camera / lights / render settings for rendering the tiling
  seed             random seed of the fibre realization (default 0)
  [yarn]           preset (data/yarns, default cotton1), radius (yarn radius, default spacing / 2.2; knitted:
                   the knit generator's 0.06 min(w, h / 0.8)),
                   fibers_per_ply (override the preset's fibre count; the fibre radius follows at the packing
                   fraction, pipeline/presets.py), fiber_radius (overrides that),
                   segment_length (fibre polyline step; default min pitch / 12), use_migration
  [weave]          spacing = [warp, weft] thread spacing (default [0.1, 0.1]), crimp (default 1),
                   block_cells = [bx, by] weave cells per block (default [1, 1])
  [knit]           (knitted exemplars) spacing = [w, h] wale and course spacing (default [0.1, 0.08]),
                   block_stitches = [bx, by] stitches per block (default [1, 1])
  [[exemplars]]    woven: pattern = plain | twill (n, m) | satin (n, step) | basket (n) | wif (path), ends,
                   picks (the exemplar size; default the draft's natural repeat), invert (swap warp and
                   weft faces: 4/1 satin -> 1/4 satin), name; a WIF's thread colours are recorded per
                   exemplar yarn (ex_yarn_color, ex_yarn_color_source; docs/wif-colours.md);
                   knitted: pattern = stockinette | garter | rib1x1, wales, courses (default the pattern's
                   repeat: 1 x 1, 1 x 2, 2 x 1), name. One tiling's exemplars are all woven or all knitted.
  [tiling]         repeat = [ru, rv] repeats of exemplar 0 over the cloth (default [2, 2]) -> the block
                   grid; block_map = PNG path or integer array (rows top to bottom, columns along u;
                   resampled nearest to the block grid), map_values (pixel value of exemplar i)
  [surface]        kind = flat | cylinder | drape | obj; size, resolution, radius, length, angle,
                   sphere_radius, folds, fold_amplitude, path (OBJ with vt), scale, offset,
                   thickness (world shell thickness, default the exemplars' thickness)
Bad input -> LoomError naming the file and key (triangles by 0-based index; exit code 2), nothing written.

``load_config`` reads and checks the configuration; the exemplars are built in ``tile_exemplars``, the
block map and base surface in ``tile_surface``; ``run_tile`` checks the surface, builds the shell
(``stages.tile.shell``) and publishes the artifact; ``load_tiling`` reads it back for rendering.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import LoomError, check_name
from ..memory import Estimate, budget as memory_budget
from ..schemas import load_schema, validate
from ..toml_file import read_toml
from .tile_exemplars import build_exemplars, exemplar_vertices, tiling_layout
from .tile_surface import block_map, build_surface


# ------------------------------------------------------------------------------------------------ config
def check_names(cfg: dict, path: Path) -> None:
    """Every value that names something names something that exists: ``surface.kind``, ``yarn.preset``
    (data/yarns/) and ``exemplars[i].pattern``; the error names the file, the key, the known names and
    the nearest one."""
    from ..presets import check_preset_name

    yarn = cfg.get("yarn")
    if isinstance(yarn, dict) and isinstance(yarn.get("preset"), str):
        check_preset_name(yarn["preset"], path, "yarn.preset")
    schema = load_schema("tile-config")["properties"]
    checks = [(cfg.get("surface"), "kind", schema["surface"]["properties"]["kind"]["enum"], "surface.kind",
               "surface kind")]
    exemplars = cfg.get("exemplars")
    patterns = schema["exemplars"]["items"]["properties"]["pattern"]["enum"]
    for i, ex in enumerate(exemplars if isinstance(exemplars, list) else ()):
        checks.append((ex, "pattern", patterns, f"exemplars[{i}].pattern", "exemplar pattern"))
    for table, key, known, place, what in checks:
        if isinstance(table, dict) and isinstance(table.get(key), str):
            check_name(table[key], known, path, place, what)


def load_config(path) -> dict:
    """The checked configuration, paths resolved; the scene it names is read (and so checked) too."""
    path = Path(path)
    cfg = read_toml(path, what="tiling configuration")
    check_names(cfg, path)
    validate(cfg, "tile-config", path)
    def res(p):
        return str(Path(p) if Path(p).is_absolute() else (path.parent / p).resolve())
    if "scene" in cfg:
        cfg["scene"] = res(cfg["scene"])
        if Path(cfg["scene"]).is_file():  # a missing scene: run_tile says "file not found" at key scene
            from ..scene import load_scene, one_fabric

            one_fabric(load_scene(cfg["scene"]), path, "scene")
    for ex in cfg["exemplars"]:
        if "path" in ex:
            ex["path"] = res(ex["path"])
    if isinstance(cfg.get("tiling", {}).get("block_map"), str):
        cfg["tiling"]["block_map"] = res(cfg["tiling"]["block_map"])
    if "path" in cfg["surface"]:
        cfg["surface"]["path"] = res(cfg["surface"]["path"])
    return cfg


# ------------------------------------------------------------------------------------------------ memory
TRIANGLE_BYTES = 1400   # a base triangle: its three shell tetrahedra (vertices, neighbours, planes, both affine maps)
VERTEX_BYTES = 200      # an exemplar fibre vertex: realized, wrapped, blocked, concatenated


def tile_estimate(cfg, config: Path, layout, nbu: int, nbv: int) -> Estimate:
    """The tile stage's peak from its configuration: the block map, the base mesh and its shell
    (two triangles per surface cell, three tetrahedra per triangle; an OBJ surface by its file size) and
    every exemplar's fibres (``tile_exemplars.exemplar_vertices``)."""
    est = Estimate("loomlight tile")
    est.add("block map", 16.0 * nbu * nbv, f"{nbu} x {nbv} blocks")
    s = cfg["surface"]
    if s["kind"] == "obj":
        tris = Path(s["path"]).stat().st_size / 10.0 if Path(s["path"]).exists() else 0.0
    else:
        nu, nv = s.get("resolution") or {"flat": (8, 8), "cylinder": (32, 8)}.get(s["kind"], (32, 32))
        tris = 2.0 * nu * nv
    est.add("shell", TRIANGLE_BYTES * tris, f"{int(tris):,} base triangles")
    verts = exemplar_vertices(cfg, config, layout)
    est.add("exemplar fibres", VERTEX_BYTES * verts, f"{int(verts):,} vertices")
    return est


# ------------------------------------------------------------------------------------------------ run
def run_tile(config, out, force: bool = False, budget=None) -> dict:
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.tile.base_surfaces import triangle_checks, vertex_normals
    from stages.tile.shell import build_shell
    from stages.tile.tiling import block_grid

    from ..artifacts import FILE, ArtifactWriter

    config = Path(config)
    cfg = load_config(config)
    s = cfg["surface"]
    if "thickness" in s and not s["thickness"] > 0:
        raise LoomError(config, "surface.thickness", f"shell thickness must be positive, got {s['thickness']}")
    inputs = {"config": config}
    if "scene" in cfg:
        inputs["scene"] = cfg["scene"]
    for k, ex in enumerate(cfg["exemplars"]):
        if "path" in ex:
            inputs[f"exemplar{k}"] = ex["path"]
    if isinstance(cfg.get("tiling", {}).get("block_map"), str):
        inputs["block_map"] = cfg["tiling"]["block_map"]
    if "path" in s:
        inputs["surface"] = s["path"]
    places = {"scene": "scene", "block_map": "tiling.block_map", "surface": "surface.path",
              **{f"exemplar{k}": f"exemplars[{k}].path" for k in range(len(cfg["exemplars"]))}}
    for name, p in inputs.items():
        if not Path(p).is_file():
            what = "is a directory, not a file" if Path(p).is_dir() else "file not found"
            raise LoomError(config, places.get(name), f"{what}: {p}")
    w = ArtifactWriter(out, kind="tiling", stage="tile", params={"config": cfg},
                       inputs={name: (p, FILE) for name, p in inputs.items()}, started=t_start)
    if not force and w.up_to_date():
        return {"skipped": True}

    # surface first: cheap checks before the fibres are realized
    exs_cfg = cfg["exemplars"]
    K = len(exs_cfg)
    layout = tiling_layout(cfg, config)
    bcx, bcy = layout.block_cells
    nbu, nbv = block_grid(cfg.get("tiling", {}).get("repeat", [2, 2]),
                          (layout.sizes[0][0] // bcx, layout.sizes[0][1] // bcy))
    tile_estimate(cfg, config, layout, nbu, nbv).check(budget or memory_budget(), config)
    bmap = block_map(cfg, config, K, nbu, nbv)
    sx, sy = layout.spacing
    bw, bh = bcx * sx, bcy * sy
    flat_size = (nbu * bw, nbv * bh)
    V, UV, F = build_surface(cfg, config, flat_size)
    N = vertex_normals(V, F)
    deg, flip = triangle_checks(V, UV, F, N)
    sfile = s.get("path", config)
    if len(deg):
        raise LoomError(sfile, f"triangle {int(deg[0])}", f"degenerate triangle (zero area in 3-D or in uv); "
                                                          f"{len(deg)} such triangle(s)")
    if len(flip):
        raise LoomError(sfile, f"triangle {int(flip[0])}", f"flipped triangle (its uv or normal orientation is "
                                                           f"opposite to the mesh's); {len(flip)} such triangle(s)")

    exs, T_ex, (bw, bh) = build_exemplars(cfg, config, layout)
    T = float(s.get("thickness", T_ex))
    shell = build_shell(V, UV, F, N, T, flat_size, T_ex)
    bad = np.flatnonzero(shell["volume"] <= 0)
    if len(bad):
        raise LoomError(sfile, f"triangle {int(bad[0]) // 3}", "the shell folds over here (a tetrahedron of the "
                        "offset prism is inverted): the thickness is too large for the surface's curvature")

    # concatenate exemplars
    cat = np.concatenate
    ex_fibers = np.cumsum([0] + [len(e["offsets"]) - 1 for e in exs]).astype(np.int64)
    pt_off = np.cumsum([0] + [len(e["points"]) for e in exs])
    seg_off = np.cumsum([0] + [len(e["points"]) - (len(e["offsets"]) - 1) for e in exs])
    ex_offsets = cat([exs[0]["offsets"][:1]] + [e["offsets"][1:] + pt_off[k] for k, e in enumerate(exs)])
    wrap_pieces_n = np.cumsum([0] + [len(e["wrap"]["offsets"]) - 1 for e in exs]).astype(np.int64)
    wpt_off = np.cumsum([0] + [len(e["wrap"]["points"]) for e in exs])
    wrap_offsets = cat([np.zeros(1, np.int64)] + [e["wrap"]["offsets"][1:] + wpt_off[k] for k, e in enumerate(exs)])
    pts = cat([e["points"] for e in exs])
    lo = pts.min(0)
    hi = pts.max(0)
    with w:
        w.write("ex_points", pts)
        w.write("ex_radius", cat([e["radius"] for e in exs]))
        w.write("ex_offsets", ex_offsets)
        w.write("ex_fiber_yarn", cat([e["fiber_yarn"] for e in exs]))
        w.write("ex_fibers", ex_fibers)
        w.write("ex_yarn_group", cat([e["yarn_group"] for e in exs]))
        w.write("ex_yarn_color", cat([c for c, _ in layout.colors]))
        w.write("ex_yarn_color_source", cat([src for _, src in layout.colors]))
        w.write("ex_over", cat([e["over"].ravel() for e in exs]).astype(np.int8))
        w.write("seg_block", cat([e["seg_block"] for e in exs]))
        w.write("ex_nblocks", np.array([e["nblocks"] for e in exs], np.int64))
        w.write("ex_period", np.array([e["period"] for e in exs], np.float64))
        w.write("block_size", np.array([bw, bh], np.float64))
        w.write("block_map", bmap)
        w.write("wrap_points", cat([e["wrap"]["points"] for e in exs]))
        w.write("wrap_radius", cat([e["wrap"]["radius"] for e in exs]))
        w.write("wrap_offsets", wrap_offsets)
        w.write("wrap_fiber",
                cat([e["wrap"]["piece_fiber"] + ex_fibers[k] for k, e in enumerate(exs)]).astype(np.int64))
        w.write("wrap_seg0", cat([e["wrap"]["piece_seg0"] + seg_off[k] for k, e in enumerate(exs)]).astype(np.int64))
        w.write("wrap_exemplar_pieces", wrap_pieces_n)
        w.write("base_vertices", V)
        w.write("base_uv", UV)
        w.write("base_triangles", F)
        w.write("base_normals", N)
        w.write("shell_vertices", shell["vertices"])
        w.write("shell_uvw", shell["uvw"])
        w.write("tets", shell["tets"])
        w.write("tet_neighbours", shell["neighbours"])
        w.write("planes", shell["planes"])
        w.write("w2f", shell["w2f"])
        w.write("f2w", shell["f2w"])
        w.write("bnd_tri", shell["bnd_tri"])
        w.write("bnd_tet", shell["bnd_tet"])
        w.write("bnd_normal", shell["bnd_normal"])
        X = shell["vertices"]
        w.summary.update(
            kind="tiling", exemplars=K, exemplar_names=[e["name"] for e in exs], blocks=int(nbu * nbv),
            block_grid=[int(nbu), int(nbv)], block_size=[bw, bh], tetrahedra=int(len(shell["tets"])),
            thickness=T, exemplar_thickness=T_ex, flat_size=list(flat_size), fibers=int(ex_fibers[-1]),
            segments=int(seg_off[-1]),
            wrapped_segments=int(len(cat([e["wrap"]["points"] for e in exs])) - wrap_pieces_n[-1]),
            exemplar_sizes=[list(e["over"].shape) for e in exs], surface=s["kind"], scene=cfg.get("scene"),
            bounds=[X.min(0).tolist(), X.max(0).tolist()], exemplar_bounds=[lo.tolist(), hi.tolist()])
        if layout.kind == "knit":  # exemplar_sizes of a weft knit: 0 ends x courses picks (tile_exemplars doc)
            w.summary.update(exemplar_kind="knit", exemplar_stitches=[list(e["stitches"].shape[::-1]) for e in exs])
    return {"skipped": False, "exemplars": K, "blocks": int(nbu * nbv), "tetrahedra": int(len(shell["tets"]))}


def load_tiling(path):
    """(ShellScene, Artifact) of a tiling artifact, ready for ``stages.core.shell.traversal``."""
    from stages.core.shell.scene import build_shell_scene

    from ..artifacts import Artifact

    art = Artifact(path, kind="tiling")
    return build_shell_scene(art), art
