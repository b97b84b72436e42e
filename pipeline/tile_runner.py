"""Stage ``tile``: exemplars, block map and shell mesh from a tiling configuration (TOML).

Configuration (``schemas/tile-config.schema.json``; relative paths against the file's directory):
  scene            scene file with camera / lights / render settings for rendering the tiling
  seed             random seed of the fibre realization (default 0)
  [yarn]           preset (data/yarns, default cotton1), radius (yarn radius, default spacing / 2.2),
                   fibers_per_ply (override the preset's fibre count), fiber_radius,
                   segment_length (fibre polyline step; default min pitch / 12), use_migration
  [weave]          spacing = [warp, weft] thread spacing (default [0.1, 0.1]), crimp (default 1),
                   block_cells = [bx, by] weave cells per block (default [1, 1])
  [[exemplars]]    pattern = plain | twill (n, m) | satin (n, step) | basket (n) | wif (path), ends,
                   picks (the exemplar size; default the draft's natural repeat), invert (swap warp and
                   weft faces: 4/1 satin -> 1/4 satin), name
  [tiling]         repeat = [ru, rv] repeats of exemplar 0 over the cloth (default [2, 2]) -> the block
                   grid; block_map = PNG path or integer array (rows top to bottom, columns along u;
                   resampled nearest to the block grid), map_values (pixel value of exemplar i)
  [surface]        kind = flat | cylinder | drape | obj; size, resolution, radius, length, angle,
                   sphere_radius, folds, fold_amplitude, path (OBJ with vt), scale, offset,
                   thickness (world shell thickness, default the exemplars' thickness)
Bad input -> LoomError naming the file and key (triangles by 0-based index; exit code 2), nothing written.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from .errors import LoomError
from .schemas import validate

DEFAULT_SPACING = 0.1


# ------------------------------------------------------------------------------------------------ config
def load_config(path) -> dict:
    path = Path(path)
    if not path.exists():
        raise LoomError(path, None, "tiling configuration not found")
    try:
        cfg = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise LoomError(path, f"line {getattr(e, 'lineno', '?')}", f"not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise LoomError(path, f"byte {e.start}", "not a UTF-8 text file") from None
    validate(cfg, "tile-config", path)
    res = lambda p: str(Path(p) if Path(p).is_absolute() else (path.parent / p).resolve())
    if "scene" in cfg:
        cfg["scene"] = res(cfg["scene"])
    for ex in cfg["exemplars"]:
        if "path" in ex:
            ex["path"] = res(ex["path"])
    if isinstance(cfg.get("tiling", {}).get("block_map"), str):
        cfg["tiling"]["block_map"] = res(cfg["tiling"]["block_map"])
    if "path" in cfg["surface"]:
        cfg["surface"]["path"] = res(cfg["surface"]["path"])
    return cfg


def _natural(ex):
    pat = ex["pattern"]
    n = ex.get("n")
    if pat == "plain":
        return 2, 2
    if pat == "twill":
        nn = n or 2
        return nn + (ex.get("m") or nn), nn + (ex.get("m") or nn)
    if pat == "satin":
        return n or 5, n or 5
    return 2 * (n or 2), 2 * (n or 2)


def exemplar_interlacement(ex, file, place):
    """(E, P) interlacement of one exemplar, checked to be periodic in the exemplar size."""
    from stages.ingest import weave

    pat = ex["pattern"]
    if pat == "wif":
        if "path" not in ex:
            raise LoomError(file, f"{place}.path", "pattern = 'wif' needs a path")
        from .io.wif import parse

        over_big = parse(ex["path"]).over
        E, P = ex.get("ends", over_big.shape[0]), ex.get("picks", over_big.shape[1])
        big = over_big
    else:
        E0, P0 = _natural(ex)
        E, P = ex.get("ends", E0), ex.get("picks", P0)

        def gen(e, p):
            if pat == "plain":
                return weave.plain(e, p)
            if pat == "twill":
                n = ex.get("n", 2)
                return weave.twill(n, ex.get("m", n), e, p)
            if pat == "satin":
                return weave.satin(ex.get("n", 5), e, p, ex.get("step"))
            return weave.basket(ex.get("n", 2), e, p)
        try:
            big = gen(2 * E, 2 * P)
        except ValueError as e:
            raise LoomError(file, place, str(e)) from None
    from stages.tile.exemplar import check_periodic_draft

    if not check_periodic_draft(big, E, P):
        raise LoomError(file, place, f"the {pat} draft ({big.shape[0]} x {big.shape[1]} shown) is not periodic in the "
                                     f"exemplar size {E} ends x {P} picks: choose a multiple of the draft's repeat")
    over = big[:E, :P].copy()
    if ex.get("invert"):
        over = ~over
    return over


# ------------------------------------------------------------------------------------------------ exemplars
def yarn_params(cfg, file):
    from stages.core.yarn import model as M

    from .presets import load_preset, pack, scale_preset

    y = cfg.get("yarn", {})
    sx, sy = cfg.get("weave", {}).get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING])
    radius = y.get("radius", min(sx, sy) / 2.2)
    try:
        d = load_preset(y.get("preset", "cotton1"))
    except LoomError as e:
        raise LoomError(file, "yarn.preset", e.message) from None
    d = scale_preset(d, float(radius))
    if "fibers_per_ply" in y:
        d["fiber_num"] = int(y["fibers_per_ply"])
    if "fiber_radius" in y:
        d["fiber_radius"] = float(y["fiber_radius"])
    if "use_migration" in y:
        d["use_migration"] = int(y["use_migration"])
    d["use_flyaways"] = 0
    tp = pack(d)
    seg = y.get("segment_length", min(tp[M.ALPHA], tp[M.YARN_ALPHA], 2 * math.pi * radius) / 12.0)
    return tp, float(radius), float(seg), d


def build_exemplars(cfg, file):
    from stages.tile.exemplar import realize_exemplar, segment_blocks, wrap_pieces

    tp, radius, seg_len, _ = yarn_params(cfg, file)
    wv = cfg.get("weave", {})
    sx, sy = wv.get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING])
    crimp = wv.get("crimp", 1.0)
    bcx, bcy = wv.get("block_cells", [1, 1])
    seed = int(cfg.get("seed", 0))
    exs = []
    for k, ex in enumerate(cfg["exemplars"]):
        place = f"exemplars[{k}]"
        over = exemplar_interlacement(ex, file, place)
        E, P = over.shape
        if E % bcx or P % bcy:
            raise LoomError(file, f"{place}", f"exemplar of {E} ends x {P} picks cannot be cut into blocks of "
                                               f"{bcx} x {bcy} cells (weave.block_cells)")
        r = realize_exemplar(over, sx, sy, tp, tp, radius, radius, crimp, seed, seg_len)
        r["over"] = over
        r["name"] = ex.get("name", f"{ex['pattern']}{k}")
        r["nblocks"] = (E // bcx, P // bcy)
        exs.append(r)
    # common exemplar space: z shifted so that every fibre surface lies in [0, T]
    zlo = min(float((e["points"][:, 2] - e["radius"]).min()) for e in exs)
    zhi = max(float((e["points"][:, 2] + e["radius"]).max()) for e in exs)
    pad = 1e-3 * (zhi - zlo)
    for e in exs:
        e["points"] = e["points"] - np.array([0.0, 0.0, zlo - pad])
    T = (zhi - zlo) + 2 * pad
    bw, bh = bcx * sx, bcy * sy
    for e in exs:
        e["wrap"] = wrap_pieces(e)
        e["seg_block"] = segment_blocks(e, bw, bh)
    return exs, T, (bw, bh)


# ------------------------------------------------------------------------------------------------ block map
def _read_png_map(path, file):
    from PIL import Image

    p = Path(path)
    if not p.exists():
        raise LoomError(file, "tiling.block_map", f"block map image not found: {p}")
    try:
        img = np.asarray(Image.open(p))
    except Exception as e:  # PIL raises many types for unreadable images
        raise LoomError(p, None, f"unreadable block map image: {e}") from None
    if img.ndim == 3:
        img = img[..., 0]
    return img.astype(np.int64)


def block_map(cfg, file, K, nbu, nbv):
    """(nbu, nbv) int32: exemplar of block (i, j) (i along u, j along v)."""
    t = cfg.get("tiling", {})
    src = t.get("block_map")
    if src is None:
        return np.zeros((nbu, nbv), np.int32)
    img = _read_png_map(src, file) if isinstance(src, str) else None
    if img is None:
        rows = src
        if len({len(r) for r in rows}) != 1:
            raise LoomError(file, "tiling.block_map", "rows of the block map differ in length")
        img = np.asarray(rows, np.int64)
    values = t.get("map_values")
    if values is not None:
        lut = {int(v): i for i, v in enumerate(values)}
        bad = sorted(set(np.unique(img).tolist()) - set(lut))
        if bad:
            raise LoomError(file, "tiling.block_map", f"map value {bad[0]} is not listed in tiling.map_values")
        img = np.vectorize(lambda v: lut[int(v)])(img)
    if img.min() < 0 or img.max() >= K:
        badv = int(img.max()) if img.max() >= K else int(img.min())
        raise LoomError(file, "tiling.block_map", f"names exemplar {badv}, but only {K} exemplar(s) "
                                                  f"(0..{K - 1}) are defined")
    from stages.tile.tiling import resample_block_map

    return resample_block_map(img, nbu, nbv)


# ------------------------------------------------------------------------------------------------ surfaces
def read_obj_mesh(path, file):
    """(V, UV, F) of a triangle/polygon OBJ mesh with vt; vertices split where uv differ."""
    p = Path(path)
    if not p.exists():
        raise LoomError(file, "surface.path", f"OBJ file not found: {p}")
    v, vt, faces = [], [], []
    for ln, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                v.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                vt.append([float(x) for x in parts[1:3]])
            elif parts[0] == "f":
                corners = []
                for c in parts[1:]:
                    ids = c.split("/")
                    if len(ids) < 2 or ids[1] == "":
                        raise LoomError(p, f"line {ln}", "face corner without a texture coordinate (v/vt): "
                                                         "shell mapping needs uv")
                    vi, ti = int(ids[0]), int(ids[1])
                    vi = vi - 1 if vi > 0 else len(v) + vi
                    ti = ti - 1 if ti > 0 else len(vt) + ti
                    if not (0 <= vi < len(v)) or not (0 <= ti < len(vt)):
                        raise LoomError(p, f"line {ln}", "face index out of range")
                    corners.append((vi, ti))
                if len(corners) < 3:
                    raise LoomError(p, f"line {ln}", "face with fewer than 3 corners")
                for k in range(1, len(corners) - 1):
                    faces.append((corners[0], corners[k], corners[k + 1]))
        except ValueError as e:
            raise LoomError(p, f"line {ln}", f"unreadable number: {e}") from None
    if not faces:
        raise LoomError(p, None, "no faces: shell mapping needs a triangle mesh")
    if not vt:
        raise LoomError(p, None, "no texture coordinates (vt): shell mapping needs uv")
    key = {}
    F = np.empty((len(faces), 3), np.int64)
    for i, f in enumerate(faces):
        for k, c in enumerate(f):
            F[i, k] = key.setdefault(c, len(key))
    pairs = np.array(list(key.keys()), np.int64)
    return np.asarray(v, float)[pairs[:, 0]], np.asarray(vt, float)[pairs[:, 1]], F


def build_surface(cfg, file, flat_size):
    from stages.tile import base_surfaces as bs

    s = cfg["surface"]
    kind = s["kind"]
    res = s.get("resolution")
    if kind == "flat":
        w, h = s.get("size", flat_size)
        nu, nv = res or (8, 8)
        V, UV, F = bs.flat_rectangle(w, h, nu, nv)
    elif kind == "cylinder":
        r = s.get("radius", flat_size[0] / math.pi)
        V, UV, F = bs.cylinder(r, s.get("length", flat_size[1]), s.get("angle", math.degrees(flat_size[0] / r)),
                               *(res or (32, 8)))
    elif kind == "drape":
        size = s.get("size", [max(flat_size)] * 2)[0]
        V, UV, F = bs.sphere_drape(size, s.get("sphere_radius", size / 4), *(res or (32, 32)),
                                   folds=s.get("folds", 6), fold_amplitude=s.get("fold_amplitude", 0.15))
    else:
        if "path" not in s:
            raise LoomError(file, "surface.path", "surface kind 'obj' needs a path")
        V, UV, F = read_obj_mesh(s["path"], file)
    V = V * s.get("scale", 1.0) + np.asarray(s.get("offset", [0.0, 0.0, 0.0]))
    return V, UV, F


# ------------------------------------------------------------------------------------------------ run
def run_tile(config, out, force: bool = False) -> dict:
    from stages.tile.base_surfaces import triangle_checks, vertex_normals
    from stages.tile.shell import build_shell
    from stages.tile.tiling import block_grid

    from .artifacts import ArtifactWriter

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
    for name, p in inputs.items():
        if not Path(p).exists():
            raise LoomError(config, name if name != "config" else None, f"file not found: {p}")
    w = ArtifactWriter(out, kind="tiling", stage="tile", params={"config": cfg}, inputs=inputs)
    if not force and w.up_to_date():
        return {"skipped": True}

    # surface first: cheap checks before the fibres are realized
    exs_cfg = cfg["exemplars"]
    K = len(exs_cfg)
    overs = [exemplar_interlacement(ex, config, f"exemplars[{k}]") for k, ex in enumerate(exs_cfg)]
    bcx, bcy = cfg.get("weave", {}).get("block_cells", [1, 1])
    nbu, nbv = block_grid(cfg.get("tiling", {}).get("repeat", [2, 2]), (overs[0].shape[0] // bcx, overs[0].shape[1] // bcy))
    bmap = block_map(cfg, config, K, nbu, nbv)
    sx, sy = cfg.get("weave", {}).get("spacing", [DEFAULT_SPACING, DEFAULT_SPACING])
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

    exs, T_ex, (bw, bh) = build_exemplars(cfg, config)
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
        w.write("ex_over", cat([e["over"].ravel() for e in exs]).astype(np.int8))
        w.write("seg_block", cat([e["seg_block"] for e in exs]))
        w.write("ex_nblocks", np.array([e["nblocks"] for e in exs], np.int64))
        w.write("ex_period", np.array([e["period"] for e in exs], np.float64))
        w.write("block_size", np.array([bw, bh], np.float64))
        w.write("block_map", bmap)
        w.write("wrap_points", cat([e["wrap"]["points"] for e in exs]))
        w.write("wrap_radius", cat([e["wrap"]["radius"] for e in exs]))
        w.write("wrap_offsets", wrap_offsets)
        w.write("wrap_fiber", cat([e["wrap"]["piece_fiber"] + ex_fibers[k] for k, e in enumerate(exs)]).astype(np.int64))
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
            segments=int(seg_off[-1]), wrapped_segments=int(len(cat([e["wrap"]["points"] for e in exs])) - wrap_pieces_n[-1]),
            exemplar_sizes=[list(e["over"].shape) for e in exs], surface=s["kind"], scene=cfg.get("scene"),
            bounds=[X.min(0).tolist(), X.max(0).tolist()], exemplar_bounds=[lo.tolist(), hi.tolist()])
    return {"skipped": False, "exemplars": K, "blocks": int(nbu * nbv), "tetrahedra": int(len(shell["tets"]))}


def load_tiling(path):
    """(ShellScene, Artifact) of a tiling artifact, ready for ``stages.core.shell.traversal``."""
    from stages.core.shell.scene import build_shell_scene

    from .artifacts import Artifact

    art = Artifact(path, kind="tiling")
    return build_shell_scene(art), art
