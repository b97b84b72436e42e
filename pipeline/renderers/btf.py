"""``--method btf``: a fitted cloth texture (seed 002) dressed on a triangle mesh.

A ``btf`` artifact (``loomlight precompute btf``) holds one repeat of a fabric as a spatially varying
BRDF, f_r = T(v) . f_1 (Lafortune lobes times a view lookup table, Daubert et al. 2001 §3), with its
mip levels. This method renders it on any triangle mesh, as the paper's §6 does, repeating the
texture over the mesh's texture coordinates. Two geometries (``--source``, else whichever is given):

- **an OBJ mesh** (``--source mesh``)::

      loomlight render SCENE.toml --method btf --set btf=BTF.zarr --set mesh=DRESS.obj --set repeat=40 -o out.exr

  The mesh needs texture coordinates (``vt``, faces as ``v/vt`` or ``v/vt/vn``) in [0, 1]; the repeat is
  laid ``repeat`` times across them (T_N of §6, a positive number, default 1): the pattern coordinate
  is frac(uv repeat). Normals: the OBJ's (``vn``) when every face corner names one, else area-weighted
  vertex normals. The pattern's x axis runs along increasing u.
- **a tiling's base surface** (``--source tiling``)::

      loomlight render SCENE.toml --method btf --set btf=BTF.zarr --fibers TILING.zarr -o out.exr

  The surface the ``tile`` stage shell-maps its exemplars onto (its vertices, normals and flat (u, v)):
  the pattern coordinate is the flat position divided by the texture's period, so one texture repeat
  covers one exemplar period, exactly where the tiling puts the exemplar; the surface is moved out along
  its normals to the top of the exemplar's fibres (the texture's ``top``: where acquisition sampled it).
  The texture must have been fitted from this tiling: its recorded source hash must be the tiling's
  content hash (a texture of another tiling's repeat is refused, naming both). On a tiling of several
  exemplars (a damask) each point of the cloth reads the texture of the exemplar the tiling's block map
  places there (the texture must hold every exemplar the map uses: ``precompute btf`` fits them all by
  default), so the figure of a damask shows as it does in ``fiberpath``. On a mesh, the texture's first
  exemplar covers it all.

Settings (``--set KEY=VALUE``):

- ``btf``: the texture (required).
- ``mesh``, ``repeat``: the OBJ and its repeat count (mesh source only).
- ``tiling``: the same as ``--fibers TILING.zarr``.
- ``mip`` = on (default) | off: on, each pixel reads the mip level whose texel matches its footprint
  on the surface (distance, incidence and the camera's pixel angle), blended linearly between the two
  nearest levels (§6.1): distant cloth is filtered instead of aliasing. off: level 0 everywhere.
  Within a level the nearest texel is read (no bilinear filter).
- ``shadows`` = off (default) | on: shadow rays from each hit towards the directional lights, through
  the mesh's surfaces with their alpha (holes let light through) and blocked by the ground.
- ``relief`` = on (default) | off: a texture acquired with a plane per texel (``precompute btf --plane relief``) is
  read where the pixel's ray meets its height field (relief mapping); off reads it where the ray crosses the
  surface, as a texture on one plane (what the relief changes). No effect on other textures.
- ``model`` = lafortune (default) | tabulated: seed 002's fit, or the acquired table itself -- r(l, v) per texel
  over the view and light grids, compressed by local PCA (``precompute btf --model tabulated``,
  ``stages.precompute.btf_compress``), decoded once per render and read bilinearly on both grids. The
  tabulated model keeps what the lobes cannot follow (the fibres' narrow glints, as far as the grids resolve
  them) at the cost of the table's bytes (``table_bytes``: 3.4 MiB an exemplar of 32 x 32 texels and 64 x 64
  directions at 8 clusters x 8 components).

Alpha: where the texture's alpha (its coverage at the view) is below 1 -- a hole in a loose weave or
knit -- the ray goes on through the surface, and the pixel is alpha x the cloth + (1 - alpha) x what
lies behind: the mesh's other side or other parts, the scene's ground (``render.ground``), or the
lights seen directly. Lights: directional lights exactly, SG lights by points of their own distribution,
constant lights by a table of the light grid's sum per texel and grid view made once per render (0.2 s for a
32 x 32 texture of 6 levels; ``sky_table``), environment maps by the sum over the texture's light grid per
pixel (``stages.render.integrators.btf``). Lights, camera and ground come from the scene;
the scene's fabric and yarns are not read. Statistics: the texture's size (``fit_bytes``: the bytes of
the arrays the renderer reads), levels, views, triangles. Integrator: ``stages.render.integrators.btf``.

Speed: nothing is random, so 1 spp is a finished image (more samples only anti-alias the edges). A
pixel costs well under a microsecond, so with several threads the shared tile loop's per-tile
overhead matters: this method's tiles are 64 pixels a side by default (``[render] tile_size``; the house's
16 elsewhere), which renders the draped cloth at 730 x 400 at about 24 frames per second on 2 threads, under
a directional light or the draped damask's own directional light and sky (``bench/bench_btf.py``); 16-pixel
tiles give about 10. The tile size does not change the picture.
"""
from __future__ import annotations

import time
from collections import namedtuple
from pathlib import Path

import numpy as np

from ..errors import LoomError
from . import RenderResult
from .settings import number_setting

# a surface to dress: vertices, triangles, unit vertex normals, vertex pattern coordinates (in repeats of the
# texture's first exemplar), and which exemplar covers which part of it (``Blocks``)
DressedMesh = namedtuple("DressedMesh", ["vertices", "triangles", "normals", "pattern_uv", "blocks", "what"])
# the texture's exemplar (its index in the texture, -1: none) per block of the flat fabric, the flat size of a
# block and of one pattern unit (``stages.render.integrators.btf``: ``block_map``, ``block_size``, ``flat_period``)
Blocks = namedtuple("Blocks", ["block_map", "block_size", "flat_period"])
ONE_EXEMPLAR = Blocks(np.zeros((1, 1), np.int64), np.ones(2), np.zeros(2))   # a mesh: the texture's first exemplar
# the texture, every level flattened and packed (``stages.render.integrators.btf`` module doc: ``texels``, ``table``,
# ``levels``), with what else the renderer needs from the artifact
BtfTexture = namedtuple("BtfTexture", ["texels", "table", "levels", "lobes", "view_grid", "light_dirs", "periods",
                                       "exemplars", "fit_bytes", "summary", "model", "radiance", "light_grid",
                                       "half", "cells", "lower", "heights", "relief_span"])
SOURCES = ("mesh", "tiling")
ON_OFF = {"on": True, "off": False}


# ------------------------------------------------------------------------------------------------ texture
def load_btf(path, model: str = "lafortune") -> BtfTexture:
    """The texture of a ``btf`` artifact, its levels flattened and checked (grids, shapes, finite values); with
    ``model`` tabulated, its compressed table decoded in the same row order (``radiance`` (N, V, L, 3) float32,
    negative values clamped to 0; else (1, 1, 1, 3) zeros). ``half``: the table's lights are half-vector cells
    (``precompute btf --light-coords half``), seen from each view cell as ``cells`` (``stages.core.btf.HalfCells``:
    valid fractions and solid angles); else None. ``lower``: the decoded table answers light from below the fabric
    (``precompute btf --light-domain sphere``; ``stages.core.btf`` SPHERE); the Lafortune fit never does.
    ``heights``: a relief texture's (``precompute btf --plane relief``) height per texel row over the surface plane
    ``plane_z`` (level 0 the artifact's ``heights``, each coarser level its texels' means), ``relief_span`` (highest,
    lowest); None for one plane."""
    from stages.core.btf import half_cell_geometry, hemisphere_grid

    from ..artifacts import Artifact

    art = Artifact(path, kind="btf")
    s = art.summary
    if not isinstance(s.get("exemplars"), list) or not s["exemplars"]:
        raise LoomError(path, "summary.exemplars", "missing: a texture written before btf artifacts held every "
                        "exemplar of a tiling; run loomlight precompute btf again")
    E = len(s["exemplars"])
    periods = np.asarray(s.get("periods"), np.float64)
    if periods.shape != (E, 2) or not np.all(np.isfinite(periods)) or not np.all(periods > 0):
        raise LoomError(path, "summary.periods",
                        f"expected a positive [W, H] per exemplar ({E}), got {s.get('periods')}")
    res, levels, K = int(s["resolution"]), int(s["levels"]), int(s["lobes"])
    nt, nph = (int(x) for x in s["view_grid"])
    lt, lph = (int(x) for x in s["light_grid"])
    coords = s.get("light_coords", "hemisphere")
    if coords not in ("hemisphere", "half"):
        raise LoomError(path, "summary.light_coords", f"must be hemisphere or half, got {coords!r}")
    half = coords == "half"
    domain = s.get("light_domain", "hemisphere")
    if domain not in ("hemisphere", "sphere"):
        raise LoomError(path, "summary.light_domain", f"must be hemisphere or sphere, got {domain!r}")
    ft, fph = (int(x) for x in s.get("fit_light_grid", [lt, lph]))
    if res & (res - 1) or not 1 <= levels <= res.bit_length():
        raise LoomError(path, "summary", f"resolution {res} with {levels} levels: the resolution must be a power "
                        f"of two and the levels at most log2(resolution) + 1")
    V = nt * nph
    names = ["view_dirs", "light_dirs"] + [f"level_{lv}/{a}" for lv in range(levels)
                                           for a in ("rho", "lobes", "table", "frame")]
    have = art.arrays()
    missing = [n for n in names if n not in have]
    if missing:
        raise LoomError(path, f"array {missing[0]}", "missing: the renderer reads every level's rho, lobes, table "
                        "and frame and the view and light directions")
    for name, grid, (a, b) in (("view_dirs", "view_grid", (nt, nph)),
                               ("light_dirs", "fit_light_grid" if half else "light_grid", (ft, fph))):
        d = np.asarray(art[name], np.float64)
        if d.shape != (a * b, 3) or not np.allclose(d, hemisphere_grid(a, b), atol=1e-5):
            raise LoomError(path, f"array {name}", f"is not the hemisphere grid of summary.{grid} = [{a}, {b}] "
                            "(stages.core.btf.hemisphere_grid): the renderer interpolates and sums on that grid")
    texels, tables, levels_rows = [], [], []
    n = 0
    stacks = []
    for lv in range(levels):
        r = res >> lv
        want = {"rho": (E, r, r, 3), "lobes": (E, r, r, K, 3, 4), "table": (E, r, r, V, 4), "frame": (E, r, r, 2, 3)}
        x = {}
        for a, shape in want.items():
            x[a] = np.asarray(art[f"level_{lv}/{a}"], np.float64)
            if x[a].shape != shape:
                raise LoomError(path, f"array level_{lv}/{a}", f"has shape {list(x[a].shape)}, expected {list(shape)} "
                                "(exemplars, texels, ...)")
            if not np.all(np.isfinite(x[a])):
                raise LoomError(path, f"array level_{lv}/{a}", "holds nan or inf")
        stacks.append(x)
    for e in range(E):                  # exemplar e's levels, finest first, then the next exemplar's
        for lv, x in enumerate(stacks):
            r = res >> lv
            nrm, tan = x["frame"][e, ..., 0, :], x["frame"][e, ..., 1, :]
            texels.append(np.concatenate([x["rho"][e], nrm, tan, np.cross(nrm, tan), x["lobes"][e].reshape(r, r, -1)],
                                         axis=-1).reshape(r * r, -1))
            tables.append(x["table"][e].reshape(r * r, V, 4))
            levels_rows.append((n, r))
            n += r * r
    fit_bytes = sum(int(np.prod(have[k].shape)) * np.dtype(have[k].dtype).itemsize for k in names)
    radiance = np.zeros((1, 1, 1, 3), np.float32)
    if model == "tabulated":
        radiance = load_table(art, path, E, res, levels, nt * nph, table_lights(s))
        fit_bytes = int(s.get("table_bytes", 0))
    heights = relief_heights(art, path, E, res, levels) if s.get("plane") == "relief" else None
    cells = None
    if half:    # the cells seen from each view cell, as the acquisition saw them (cell averages or centres)
        cells = half_cell_geometry(nt, nph, lt, lph, s.get("directions", "cell") == "cell")
    return BtfTexture(np.ascontiguousarray(np.concatenate(texels)),
                      np.ascontiguousarray(np.concatenate(tables), np.float32),
                      np.asarray(levels_rows, np.int64).reshape(E, levels, 2), K, (nt, nph),
                      np.ascontiguousarray(art["light_dirs"], np.float64), periods,
                      [int(k) for k in s["exemplars"]], fit_bytes, s, model, radiance, (lt, lph), half, cells,
                      model == "tabulated" and domain == "sphere", heights,
                      None if heights is None else (float(heights.max()), float(heights.min())))


def relief_heights(art, path, E, res, levels) -> np.ndarray:
    """A relief texture's heights over its surface plane per texel row, in ``load_btf``'s row order (exemplar,
    level, texel): level 0 the artifact's ``heights`` less ``plane_z``, each coarser level the mean of its 2 x 2
    texels below."""
    if "heights" not in art.arrays():
        raise LoomError(path, "array heights", "missing: summary.plane is relief, whose texels each have a height "
                        "(precompute btf --plane relief writes it)")
    h = np.asarray(art["heights"], np.float64)
    if h.shape != (E, res, res) or not np.all(np.isfinite(h)):
        raise LoomError(path, "array heights", f"has shape {list(h.shape)} or holds nan/inf, expected finite "
                        f"heights of shape {[E, res, res]}")
    h = h - float(art.summary["plane_z"])
    rows = []
    for e in range(E):
        lv = h[e]
        for _ in range(levels):
            rows.append(lv.ravel())
            if lv.shape[0] > 1:
                lv = 0.25 * (lv[0::2, 0::2] + lv[1::2, 0::2] + lv[0::2, 1::2] + lv[1::2, 1::2])
    return np.ascontiguousarray(np.concatenate(rows))


def table_lights(summary) -> int:
    """The tabulated table's light cells: the light grid's, twice for a table with light from below
    (``light_domain`` sphere: the grid and its mirror below the fabric)."""
    return int(np.prod(summary["light_grid"])) * (2 if summary.get("light_domain") == "sphere" else 1)


def load_table(art, path, E, res, levels, V, L) -> np.ndarray:
    """The tabulated model's table of every exemplar, decoded (``stages.core.btf.decode_texels``, negative values
    clamped to 0): (N, V, L, 3) float32, rows as ``load_btf``'s (exemplar, level, row-major texel)."""
    from stages.core.btf import decode_texels

    have = art.arrays()
    if "tabulated/weights" not in have:
        raise LoomError(path, "array tabulated/weights", "missing: the texture holds the Lafortune fit only; run "
                        "loomlight precompute btf --model tabulated (it reuses the acquisition) or render with "
                        "--set model=lafortune")
    rows = sum((res >> lv) ** 2 for lv in range(levels))
    cluster = np.asarray(art["tabulated/cluster"], np.int32)
    mean = np.asarray(art["tabulated/mean"], np.float32)
    basis = np.asarray(art["tabulated/basis"], np.float32)
    weights = np.asarray(art["tabulated/weights"], np.float32)
    C, K = basis.shape[1], basis.shape[2]
    for name, a, shape in (("cluster", cluster, (E, rows)), ("mean", mean, (E, C, V, L, 3)),
                           ("basis", basis, (E, C, K, V, L, 3)), ("weights", weights, (E, rows, K))):
        if a.shape != shape:
            raise LoomError(path, f"array tabulated/{name}", f"has shape {list(a.shape)}, expected {list(shape)} "
                            "(exemplars, texels of every level, clusters, components, views, lights, channels)")
        if not np.all(np.isfinite(a)):
            raise LoomError(path, f"array tabulated/{name}", "holds nan or inf")
    if cluster.size and (cluster.min() < 0 or cluster.max() >= C):
        raise LoomError(path, "array tabulated/cluster", f"holds a cluster outside 0..{C - 1}")
    out = np.empty((E, rows, V * L * 3), np.float32)
    for e in range(E):
        decode_texels(cluster[e], mean[e].reshape(C, -1), basis[e].reshape(C, K, -1), weights[e], out[e], True)
    return out.reshape(E * rows, V, L, 3)


# ------------------------------------------------------------------------------------------------ geometry
def load_obj(path, repeat: float) -> DressedMesh:
    """The OBJ at ``path`` (``--set mesh``) dressed with ``repeat`` texture repeats across its uv."""
    from stages.core.geometry.triangles import area_weighted_normals

    from ..io.obj_mesh import read_obj_mesh

    p = Path(path)
    if p.is_dir():
        raise LoomError(p, "--set mesh", "is a directory; give a Wavefront OBJ triangle mesh file (.obj)")
    if not p.is_file():
        raise LoomError(p, "--set mesh", "mesh file not found")
    if p.suffix.lower() != ".obj":
        raise LoomError(p, "--set mesh", f"is not a Wavefront OBJ mesh (suffix {p.suffix or 'none'}); the btf method "
                        "renders an .obj triangle mesh with texture coordinates")
    V, UV, F, N = read_obj_mesh(p, p, normals=True, uv_for="the btf method places its texture by the mesh's uv")
    if not (np.all(np.isfinite(V)) and np.all(np.isfinite(UV))):
        raise LoomError(p, None, "vertex or texture coordinates hold nan or inf")
    what = "its normals"
    if N is None:
        N = area_weighted_normals(V, F)
        what = "area-weighted normals"
    return DressedMesh(V, F, N, UV * repeat, ONE_EXEMPLAR, f"{p.name} ({len(F)} triangles, {what}, repeat {repeat:g})")


def load_tiling_surface(path, btf_path, tex: BtfTexture) -> DressedMesh:
    """A tiling's base surface (``--fibers``) dressed with the textures fitted from its exemplars, each where the
    tiling's block map places that exemplar."""
    from ..artifacts import Artifact

    art = Artifact(path, kind="tiling")
    s = tex.summary
    mine = art.meta.get("content_hash")
    names = art.summary.get("exemplar_names") or []
    if s.get("source_hash") != mine:
        fitted = ", ".join(f"{k} ('{n}')" for k, n in zip(s.get("exemplars", []), s.get("exemplar_names", [])))
        raise LoomError(btf_path, "summary.source_hash",
                        f"a BTF from a different repeat than the scene names: {btf_path} was fitted to exemplar(s) "
                        f"{fitted} of {s.get('source')} (content hash "
                        f"{str(s.get('source_hash'))[:12]}), but the tiling is {path} (exemplars "
                        f"{', '.join(repr(x) for x in names)}, content hash {str(mine)[:12]}); run loomlight "
                        f"precompute btf on {path}")
    tiling_map = np.asarray(art["block_map"], np.int64)
    index = {k: i for i, k in enumerate(tex.exemplars)}
    used = sorted(int(k) for k in np.unique(tiling_map) if k >= 0)
    missing = [k for k in used if k not in index]
    if missing:
        name = names[missing[0]] if missing[0] < len(names) else "?"
        raise LoomError(btf_path, "summary.exemplars",
                        f"has no texture of exemplar {missing[0]} ('{name}'), "
                        f"which the block map of {path} uses (the texture holds {tex.exemplars}); run loomlight "
                        "precompute btf without --exemplar")
    to_texture = np.full(max(used + [0]) + 1, -1, np.int64)   # tiling exemplar -> its index in the texture
    for k in used:
        to_texture[k] = index[k]
    block_map = np.where(tiling_map >= 0, to_texture[np.clip(tiling_map, 0, len(to_texture) - 1)], -1)
    p0 = tex.periods[0]
    blocks = Blocks(np.ascontiguousarray(block_map, np.int64), np.asarray(art["block_size"], np.float64), p0.copy())
    flat = np.asarray(art.summary["flat_size"], np.float64)
    scale = flat / p0   # base uv in [0, 1] spans flat_size; one repeat (of the first exemplar) = its period
    N = np.asarray(art["base_normals"], np.float64)
    N = N / np.maximum(np.linalg.norm(N, axis=1), 1e-300)[:, None]
    # the texture lives on its plane (seed 002 §4: the top face of the repeat's box; ``precompute btf --plane``):
    # the base surface moved out along its normals to that height (the shell's flat z is world length there)
    V = np.asarray(art["base_vertices"], np.float64) + float(s.get("plane_z", s.get("top", 0.0))) * N
    F = np.asarray(art["base_triangles"], np.int64)
    return DressedMesh(V, F, N, np.asarray(art["base_uv"], np.float64) * scale[None, :], blocks,
                       f"{Path(path).name} base surface ({len(F)} triangles, {len(used)} exemplar(s))")


# ------------------------------------------------------------------------------------------------ setup
def geometry_source(scene, options) -> str:
    """'mesh' or 'tiling': ``--source``, the scene's ``render.source`` when it names one of them, else the
    geometry given (``--set mesh`` or ``--fibers``); both or neither given is an error."""
    extra = options.get("extra") or {}
    src = options.get("source") or (scene.render.get("source") if scene.render.get("source") in SOURCES else None)
    mesh, tiling = extra.get("mesh"), options.get("fibers")
    if mesh and tiling:
        raise LoomError(None, "--set mesh", "btf renders one geometry: an OBJ (--set mesh=PATH.obj) or a tiling's "
                                            "surface (--fibers TILING.zarr), not both")
    src = src or ("tiling" if tiling else "mesh")
    if src == "mesh" and not mesh:
        raise LoomError(None, "--set mesh", "btf needs a geometry: an OBJ with texture coordinates (--set "
                                            "mesh=PATH.obj --set repeat=N) or a tiling (--fibers TILING.zarr)")
    if src == "tiling" and extra.get("repeat") is not None:
        raise LoomError(None, "--set repeat", "applies to --set mesh only: on a tiling, one texture repeat covers "
                                              "one exemplar period")
    return src


def pack_integrator(geom: DressedMesh, tex: BtfTexture, lights, ground, has_ground, cam, mip: bool, shadows: bool):
    """The ``BtfIntegrator`` of a dressed mesh and a texture under a camera (``pack_camera`` layout)."""
    from stages.core.btf import hemisphere_grid
    from stages.core.geometry.triangles import build_triangle_mesh, uv_derivatives
    from stages.render.camera import CAM_FORWARD, CAM_TAN_HALF_FOV, CAM_WIDTH
    from stages.render.integrators.btf import MAX_LAYERS, SHADING_SIZE, BtfIntegrator, sky_table, tabulated_sky_table
    from stages.render.lights import CONSTANT, DIRECTIONAL, ENVMAP

    from ..render_setup import ray_eps

    V, F = geom.vertices, geom.triangles
    mesh = build_triangle_mesh(V, F)
    dpdx, dpdy = uv_derivatives(V, geom.pattern_uv, F)

    def unit(a):
        n = np.linalg.norm(a, axis=1)
        return a / np.where(n > 0, n, 1.0)[:, None]
    shading = np.empty((len(F), SHADING_SIZE))
    shading[:, 0:9] = geom.normals[F].reshape(-1, 9)
    shading[:, 9:15] = geom.pattern_uv[F].reshape(-1, 6)
    shading[:, 15:18] = unit(dpdx)
    shading[:, 18:21] = unit(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]))
    shading[:, 21] = np.sqrt(np.linalg.norm(np.cross(dpdx, dpdy), axis=1)) / float(tex.levels[0, 0, 1])
    table = lights.table()
    kinds = table.lights[:, 0]
    quad = int(np.count_nonzero(kinds != DIRECTIONAL))
    env = int(np.count_nonzero(kinds == ENVMAP))
    constant = kinds == CONSTANT
    has_sky = bool(constant.any())
    tabulated = tex.model == "tabulated"
    # a constant light's quadrature, per texel and grid view, once (``stages.render.integrators.btf.sky_table``)
    if not has_sky:
        sky = np.zeros((1, 1, 3), np.float32)
    elif tabulated:
        sky = tabulated_sky_table(tex.radiance, sky_weights(tex))
    else:
        sky = sky_table(tex.texels, tex.light_dirs, hemisphere_grid(*tex.view_grid))
    tab = tex.table
    if tabulated:   # the table's r(l, v) is the whole f_r: T(v) = 1, alpha kept
        tab = tab.copy()
        tab[..., :3] = 1.0
    sky_radiance = np.ascontiguousarray(table.lights[constant, 1:4].sum(axis=0), np.float64)
    eps = ray_eps(V.min(0), V.max(0)) if len(V) else 1e-9
    pixel_angle = 2.0 * float(cam[CAM_TAN_HALF_FOV]) / float(cam[CAM_WIDTH])
    return BtfIntegrator(mesh, shading, tex.texels, tab, tex.levels,
                         np.ascontiguousarray(tex.periods[0][None, :] / tex.periods), geom.blocks.block_map,
                         geom.blocks.block_size, geom.blocks.flat_period, int(tex.view_grid[0]),
                         int(tex.view_grid[1]), tex.light_dirs, table, quad, env, sky, sky_radiance, has_sky, ground,
                         has_ground, pixel_angle,
                         np.ascontiguousarray(cam[CAM_FORWARD:CAM_FORWARD + 3], np.float64), bool(mip),
                         int(bool(shadows)), MAX_LAYERS, eps, tabulated, tex.radiance, int(tex.light_grid[0]),
                         int(tex.light_grid[1]), int(tex.half), tex.cells.valid if tex.half else np.ones((1, 1)),
                         bool(tex.lower), *relief_fields(tex))


def relief_fields(tex: BtfTexture):
    """The integrator's ``heights``, ``relief``, ``relief_span`` and ``inv_period`` (``stages.render.integrators.btf``
    "Relief")."""
    if tex.heights is None:
        return np.zeros(1), False, np.zeros(2), np.zeros(2)
    return (tex.heights, True, np.asarray(tex.relief_span, np.float64),
            np.ascontiguousarray(1.0 / tex.periods[0], np.float64))


def sky_weights(tex: BtfTexture) -> np.ndarray:
    """(V, L) the tabulated table's quadrature weights per view cell and light cell: 2 pi / n on the hemisphere grid
    of n cells (every cell the same solid angle; a sphere table's 2 n cells too: the sky below counts); a
    half-vector cell's solid angle over its valid fraction (its cell average
    counts the invalid part as 0; ``stages.core.btf`` module doc), 0 where it has no light."""
    from stages.core.btf import MIN_VALID

    V, n = tex.table.shape[1], tex.light_grid[0] * tex.light_grid[1]
    if not tex.half:
        return np.full((V, n * (2 if tex.lower else 1)), 2.0 * np.pi / n)
    valid, solid = tex.cells
    return np.where(valid >= MIN_VALID, solid / np.maximum(valid, MIN_VALID), 0.0)


def film_setup(scene, options: dict):
    """The ``FilmSetup`` of a btf render (``pipeline.renderers.film``): integrator, camera, label."""
    from stages.render.film import VARIANCE_CHANNELS

    from ..render_setup import ground_array, pack_lights
    from ..scene import camera_array
    from .film import FilmSetup

    extra = options.get("extra") or {}
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    lights = pack_lights(scene.lights, scene.path)
    if len(lights.lights) == 0:
        raise LoomError(scene.path, "lights", "the scene has no lights (the image would be black)")
    btf_path = options.get("btf") or extra.get("btf")
    if not btf_path:
        raise LoomError(None, "--set btf", "btf needs the fitted texture: pass --set btf=PATH.zarr (loomlight "
                                           "precompute btf)")
    src = geometry_source(scene, options)
    repeat = number_setting(extra, "repeat", 1.0, above=0.0, what="texture repeats across uv [0, 1]")
    t0 = time.perf_counter()
    model = extra.get("model", "lafortune")
    tex = load_btf(btf_path, model)
    if src == "mesh":
        geom = load_obj(extra["mesh"], repeat)
    else:
        geom = load_tiling_surface(options["fibers"], btf_path, tex)
    mip = ON_OFF[extra.get("mip", "on")]
    shadows = ON_OFF[extra.get("shadows", "off")]
    if not ON_OFF[extra.get("relief", "on")]:
        tex = tex._replace(heights=None, relief_span=None)
    ground, has_ground = ground_array(scene.render)
    cam = camera_array(scene.camera, options["width"], options["height"])
    integ = pack_integrator(geom, tex, lights, ground, has_ground, cam, mip, shadows)
    load_s = time.perf_counter() - t0
    stats = {"load_s": load_s, "geometry": geom.what, "source": src, "triangles": int(len(geom.triangles)),
             "bvh_nodes": int(len(integ.mesh.nodes)), "btf_resolution": int(tex.levels[0, 0, 1]),
             "btf_levels": int(tex.levels.shape[1]), "btf_exemplars": int(tex.levels.shape[0]),
             "btf_lobes": int(tex.lobes), "btf_model": model,
             "btf_light_domain": "sphere" if tex.lower else "hemisphere",
             "btf_views": int(tex.table.shape[1]), "btf_lights": int(len(tex.light_dirs)),
             "fit_bytes": int(tex.fit_bytes), "mip": "on" if mip else "off", "shadows": "on" if shadows else "off",
             "relief": "on" if integ.relief else "off", "max_layers": int(integ.max_layers)}
    return FilmSetup("btf", integ, cam, VARIANCE_CHANNELS, stats)


def render(scene, options: dict) -> RenderResult:
    from .film import render_with_film

    s, run = render_with_film(__name__, scene, options)
    return RenderResult(run.rgb, run.extra, {**run.stats(), **s.stats})
