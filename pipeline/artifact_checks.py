"""Summaries checked against arrays: the one place, per artifact kind, where every count, shape and
order a reader takes from an artifact's summary is compared with the shapes of the artifact's own
arrays, when the artifact is opened (``pipeline.artifacts.Artifact``).

The content hash shows that a summary was not edited by accident; it cannot show that a summary
whose hash was recomputed tells the truth. A reader that trusted such a summary would index past its
arrays (a tiling claiming 10 exemplars where it holds 2), broadcast wrong shapes (an SVF whose
resolution was edited) or silently read its arrays another way (an IIRTF whose SH order was edited:
another picture). So an artifact whose summary disagrees with its arrays is refused, naming the key
(``summary.exemplars``), what it says and what the arrays hold.

Only the arrays' recorded shapes are used (``{name: {"dtype", "shape"}}``, read from their zarr.json
files): no array is loaded, numpy is not imported, and ``loomlight info`` stays a metadata read. A kind
without a function here is checked by its schema alone. Relations between two artifacts (an SVF and
the tiling it was computed from) are checked where both are open, by the reader
(``pipeline.renderers.prt``).
"""
from __future__ import annotations

from pathlib import Path

from .errors import LoomError

REBUILD = "the summary does not describe the artifact's arrays (edited?); rebuild it with its stage"


class _Arrays:
    """The arrays' shapes, and the refusals: each names the summary key at fault."""

    def __init__(self, path: Path, kind: str, summary: dict, arrays: dict):
        self.path, self.kind, self.summary, self.arrays = path, kind, summary, arrays

    def shape(self, name: str) -> list[int] | None:
        rec = self.arrays.get(name)
        return None if rec is None else list(rec["shape"])

    def need(self, name: str, key: str) -> list[int]:
        s = self.shape(name)
        if s is None:
            raise LoomError(self.path, f"array {name}", f"missing, but {self.kind} readers need it (summary.{key}); "
                            "rebuild it with its stage")
        return s

    def rows(self, name: str, key: str) -> int:
        s = self.need(name, key)
        if not s:
            raise LoomError(self.path, f"array {name}", "is a scalar, expected an array; rebuild it with its stage")
        return s[0]

    def value(self, key: str, kind=int):
        """The summary's ``key`` as readers use it: an integer (not a bool), or a list."""
        v = self.summary.get(key)
        if kind is int and (not isinstance(v, int) or isinstance(v, bool)):
            raise LoomError(self.path, f"summary.{key}", f"must be an integer, got {v!r}; {REBUILD}")
        if kind is list and not isinstance(v, list):
            raise LoomError(self.path, f"summary.{key}", f"must be a list, got {v!r}; {REBUILD}")
        return v

    def same(self, key: str, says, holds, what: str, shown: str | None = None) -> None:
        """Refuse unless the summary's ``says`` (at ``key``; ``shown`` as the message tells it) equals
        ``holds``, which ``what`` tells (the arrays' count)."""
        if says != holds:
            raise LoomError(self.path, f"summary.{key}", f"says {says if shown is None else shown}, but {what}; "
                            f"{REBUILD}")

    def shaped(self, name: str, want: list, keys: str) -> None:
        """Refuse unless array ``name`` has shape ``want`` (implied by the summary's ``keys``)."""
        have = self.need(name, keys)
        if have != list(want):
            raise LoomError(self.path, f"array {name}", f"has shape {have}, but summary {keys} imply {list(want)}; "
                            f"{REBUILD}")

    def dim(self, name: str, axis: int, key: str) -> int:
        """Axis ``axis`` of array ``name``, which summary ``key`` describes."""
        s = self.need(name, key)
        if len(s) <= axis:
            raise LoomError(self.path, f"array {name}", f"has shape {s}, expected at least {axis + 1} axes; "
                            "rebuild it with its stage")
        return s[axis]

    def agree(self, name: str, rows: int, what: str) -> None:
        """Refuse unless array ``name`` has ``rows`` rows, as ``what`` implies (two arrays disagree)."""
        have = self.rows(name, "?")
        if have != rows:
            raise LoomError(self.path, f"array {name}", f"has {have} rows, but {what} implies {rows}; the arrays "
                            "disagree: rebuild it with its stage")


def _length(a: _Arrays, key: str, holds: int, what: str) -> None:
    v = a.summary.get(key)
    if v is not None:
        n = len(a.value(key, list))
        a.same(key, n, holds, f"{what} {holds}", f"{n} entries")


def _tiling(a: _Arrays) -> None:
    K = a.rows("ex_fibers", "exemplars") - 1
    a.same("exemplars", a.value("exemplars"), K, f"array ex_fibers holds the fibre ranges of {K} exemplars")
    for name in ("ex_nblocks", "ex_period"):
        a.agree(name, K, "array ex_fibers (exemplars)")
    a.agree("wrap_exemplar_pieces", K + 1, "array ex_fibers (exemplars + 1)")
    for key in ("exemplar_names", "exemplar_sizes", "exemplar_stitches"):
        _length(a, key, K, "the arrays hold exemplars:")
    F = a.rows("ex_offsets", "fibers") - 1
    a.same("fibers", a.value("fibers"), F, f"array ex_offsets holds the point ranges of {F} fibres")
    a.agree("ex_fiber_yarn", F, "array ex_offsets (fibres)")
    P = a.rows("ex_points", "segments")
    a.agree("ex_radius", P, "array ex_points (points)")
    a.same("segments", a.value("segments"), P - F, f"arrays ex_points and ex_offsets hold {P - F} segments "
           f"({P} points of {F} fibres)")
    a.agree("seg_block", P - F, "arrays ex_points and ex_offsets (segments)")
    sizes = a.summary.get("exemplar_sizes")
    if isinstance(sizes, list) and all(isinstance(s, list) and len(s) == 2 for s in sizes):
        yarns = sum(int(e) + int(p) for e, p in sizes)
        Y = a.rows("ex_yarn_group", "exemplar_sizes")
        a.same("exemplar_sizes", yarns, Y, f"array ex_yarn_group holds {Y} yarns", f"{yarns} yarns (ends + picks)")
        for name in ("ex_yarn_color", "ex_yarn_color_source"):
            if a.shape(name) is not None:
                a.agree(name, yarns, "summary.exemplar_sizes and array ex_yarn_group (yarns)")
        if a.shape("ex_over") is not None:
            n = sum(int(e) * int(p) for e, p in sizes)
            over = a.rows("ex_over", "exemplar_sizes")
            a.same("exemplar_sizes", n, over, f"array ex_over holds {over} crossings", f"{n} crossings (ends x picks)")
    grid = a.value("block_grid", list)
    bm = a.need("block_map", "block_grid")
    a.same("block_grid", grid, bm, f"array block_map has the shape {bm}")
    a.same("blocks", a.value("blocks"), grid[0] * grid[1], f"block_grid (block_map's shape) holds {grid[0] * grid[1]}")
    T = a.rows("tets", "tetrahedra")
    a.same("tetrahedra", a.value("tetrahedra"), T, f"array tets holds {T}")
    for name in ("tet_neighbours", "planes", "w2f", "f2w"):
        a.agree(name, T, "array tets (tetrahedra)")


def _packed_bytes(R: int, C: int) -> int:
    return (R * C + 7) // 8  # stages.precompute.svf.packed_bytes (no numpy here)


def _exemplar_entries(a: _Arrays) -> list[dict]:
    entries = a.value("exemplars", list)
    seen = set()
    for i, e in enumerate(entries):
        k = e.get("exemplar")
        if k in seen:
            raise LoomError(a.path, f"summary.exemplars[{i}].exemplar", f"exemplar {k} is listed twice; {REBUILD}")
        seen.add(k)
        if a.shape(f"exemplar_{k}/{'visibility' if a.kind == 'svf' else 'transfer'}") is None:
            raise LoomError(a.path, f"summary.exemplars[{i}].exemplar", f"says {k}, but the artifact has no group "
                            f"exemplar_{k}; {REBUILD}")
    groups = sorted({n.split("/", 1)[0] for n in a.arrays if n.startswith("exemplar_") and "/" in n})
    extra = [g for g in groups if g not in {f"exemplar_{k}" for k in seen}]
    if extra:
        raise LoomError(a.path, "summary.exemplars",
                        f"does not list group {extra[0]}, which the artifact holds; {REBUILD}")
    return entries


def _svf(a: _Arrays) -> None:
    res = a.value("resolution", list)
    if not (len(res) == 2 and all(isinstance(x, int) and not isinstance(x, bool) for x in res)):
        raise LoomError(a.path, "summary.resolution", f"must be two integers, got {res!r}; {REBUILD}")
    R, C = res
    n, Q = a.value("components"), a.value("sg_count")
    total = 0
    for i, e in enumerate(_exemplar_entries(a)):
        g = f"exemplar_{e['exemplar']}/"
        D = a.dim(g + "ssdf_mean", 0, "resolution")
        a.same("resolution", R * C, D, f"array {g}ssdf_mean holds {D} pixels", f"{R} x {C} = {R * C} pixels")
        nb = a.dim(g + "ssdf_basis", 0, "components")
        a.same("components", n, nb, f"array {g}ssdf_basis holds {nb}")
        q = a.dim(g + "sg_weights", 1, "sg_count")
        a.same("sg_count", Q, q, f"array {g}sg_weights holds {q} SGs")
        S = e.get("segments")
        Sv = a.dim(g + "visibility", 0, f"exemplars[{i}].segments")
        a.same(f"exemplars[{i}].segments", S, Sv, f"array {g}visibility holds {Sv} segments' images")
        lo, hi = e.get("segment_range", [0, 0])
        a.same(f"exemplars[{i}].segment_range", hi - lo, S, f"its segments says {S}", f"{hi - lo} segments")
        keys = f"resolution, components, sg_count and exemplars[{i}].segments"
        for name, want in (("visibility", [S, _packed_bytes(R, C)]), ("ssdf_mean", [R * C]), ("ssdf_basis", [n, R * C]),
                           ("ssdf_coeffs", [S, n]), ("sg_weights", [S, Q]), ("sg_angle", [S])):
            a.shaped(g + name, want, keys)
        if a.shape(g + "segment_ids") is not None:
            a.shaped(g + "segment_ids", [S], keys)
        total += S
    a.same("segments", a.value("segments"), total, f"its exemplars hold {total}")


def _iirtf(a: _Arrays) -> None:
    L = a.value("order")
    J = (L + 1) ** 2
    Ja = a.dim("bcsdf_sh", 2, "order")
    a.same("order", J, Ja, f"array bcsdf_sh holds {Ja} SH coefficients per direction",
           f"{L} ((L + 1)^2 = {J} SH coefficients)")
    if "sh_coefficients" in a.summary:
        a.same("sh_coefficients", a.value("sh_coefficients"), J, f"order {L} implies (L + 1)^2 = {J}")
    M = a.value("materials")
    m = a.rows("materials", "materials")
    a.same("materials", M, m, f"array materials holds {m}")
    if "theta_samples" in a.summary:
        t = a.dim("bcsdf_sh", 1, "theta_samples")
        a.same("theta_samples", a.value("theta_samples"), t, f"array bcsdf_sh holds {t}")
    a.shaped("bcsdf_sh", [M, a.dim("bcsdf_sh", 1, "theta_samples"), J, 3], "materials, theta_samples and order")
    stored = cells = 0
    for i, e in enumerate(_exemplar_entries(a)):
        g = f"exemplar_{e['exemplar']}/"
        N, Cc, S = e.get("stored_cells"), e.get("cells"), e.get("segments")
        prod = 1
        for v in e.get("cell_grid") or []:
            prod *= v
        a.same(f"exemplars[{i}].cells", Cc, prod, f"its cell_grid holds {prod}")
        Nt = a.dim(g + "transfer", 0, f"exemplars[{i}].stored_cells")
        a.same(f"exemplars[{i}].stored_cells", N, Nt, f"array {g}transfer holds {Nt}")
        Cr = a.dim(g + "cell_row", 0, f"exemplars[{i}].cells")
        a.same(f"exemplars[{i}].cells", Cc, Cr, f"array {g}cell_row holds {Cr}")
        Sr = a.dim(g + "seg_row", 0, f"exemplars[{i}].segments")
        a.same(f"exemplars[{i}].segments", S, Sr, f"array {g}seg_row holds {Sr}")
        keys = f"order and exemplars[{i}] (stored_cells, cells, segments)"
        for name, want in (("transfer", [N, 3, J, J]), ("transfer_se", [N, 3, J, J]), ("row_cell", [N]),
                           ("row_segments", [N]), ("cell_row", [Cc]), ("seg_row", [S])):
            a.shaped(g + name, want, keys)
        if "layer_bins" in a.summary:   # IIRTFs made before 2026-12-07 have no layer transmittance
            for name in ("layer_tau", "layer_tau_se"):
                a.shaped(g + name, [2, a.value("layer_bins"), 3], "layer_bins (2 sides x bins x RGB)")
        stored += N
        cells += Cc
    for key, holds in (("stored_cells", stored), ("cells", cells)):
        if key in a.summary:
            a.same(key, a.value(key), holds, f"its exemplars hold {holds}")


def _btf(a: _Arrays) -> None:
    res, levels, K = a.value("resolution"), a.value("levels"), a.value("lobes")
    nt, nph = a.value("view_grid", list)
    lt, lph = a.value("light_grid", list)
    E = len(a.value("exemplars", list))
    have = len({n.split("/", 1)[0] for n in a.arrays if n.startswith("level_") and "/" in n})
    a.same("levels", levels, have, f"the artifact holds {have} level groups")
    e0 = a.dim("level_0/rho", 0, "exemplars")
    a.same("exemplars", E, e0, f"array level_0/rho holds {e0} exemplar(s)")
    r0 = a.dim("level_0/rho", 1, "resolution")
    a.same("resolution", res, r0, f"array level_0/rho holds {r0} x {r0} texels")
    k0 = a.dim("level_0/lobes", 3, "lobes")
    a.same("lobes", K, k0, f"array level_0/lobes holds {k0}")
    v = a.rows("view_dirs", "view_grid")
    a.same("view_grid", nt * nph, v, f"array view_dirs holds {v} views", f"{nt} x {nph} = {nt * nph} views")
    half = a.summary.get("light_coords", "hemisphere") == "half"   # half-vector cells: light_dirs is the fit's grid
    fkey = "fit_light_grid" if half else "light_grid"
    ft, fph = a.value(fkey, list)
    li = a.rows("light_dirs", fkey)
    a.same(fkey, ft * fph, li, f"array light_dirs holds {li} lights", f"{ft} x {fph} = {ft * fph} lights")
    for lv in range(levels):
        r = res >> lv
        for name, want in (("rho", [E, r, r, 3]), ("lobes", [E, r, r, K, 3, 4]), ("table", [E, r, r, nt * nph, 4]),
                           ("frame", [E, r, r, 2, 3])):
            a.shaped(f"level_{lv}/{name}", want, "exemplars, resolution, levels, lobes and view_grid")
    a.shaped("view_dirs", [nt * nph, 3], "view_grid")
    a.shaped("light_dirs", [ft * fph, 3], fkey)
    if half:
        a.shaped("half_dirs", [lt * lph, 3], "light_grid")
    if a.summary.get("plane") == "relief":     # a plane per texel (precompute btf --plane relief)
        a.shaped("heights", [E, res, res], "exemplars, resolution and plane")
    if "tabulated/weights" in a.arrays:     # the tabulated model (precompute btf --model tabulated)
        C, K = a.value("table_clusters"), a.value("table_components")
        T = sum((res >> lv) ** 2 for lv in range(levels))
        keys = ("exemplars, resolution, levels, view_grid, light_grid, light_domain, table_clusters and "
                "table_components")
        nl = lt * lph * (2 if a.summary.get("light_domain", "hemisphere") == "sphere" else 1)   # and mirrored below
        for name, want in (("cluster", [E, T]), ("mean", [E, C, nt * nph, nl, 3]),
                           ("basis", [E, C, K, nt * nph, nl, 3]), ("weights", [E, T, K]),
                           ("rel_rmse_by_components", [E, K + 1])):
            a.shaped(f"tabulated/{name}", want, keys)


def _yarns(a: _Arrays) -> None:
    N = a.rows("curve_offsets", "curves") - 1
    a.same("curves", a.value("curves"), N, f"array curve_offsets holds the point ranges of {N} curves")
    P = a.rows("points", "control_points")
    a.same("control_points", a.value("control_points"), P, f"array points holds {P}")
    for name in ("closed", "group", "yarn_type"):
        a.agree(name, N, "array curve_offsets (curves)")


def _fibers(a: _Arrays) -> None:
    F = a.rows("fiber_offsets", "fibers") - 1
    a.same("fibers", a.value("fibers"), F, f"array fiber_offsets holds the point ranges of {F} fibres")
    for name in ("fiber_yarn", "fiber_ply", "fiber_kind"):
        a.agree(name, F, "array fiber_offsets (fibres)")
    V = a.rows("points", "vertices")
    a.same("vertices", a.value("vertices"), V, f"array points holds {V}")
    a.agree("point_radius", V, "array points (vertices)")
    Y = a.rows("yarn_albedo", "yarns")
    a.same("yarns", a.value("yarns"), Y, f"array yarn_albedo holds {Y}")


def _grid(a: _Arrays) -> None:
    res = a.value("resolution", list)
    if not (isinstance(res, list) and len(res) == 3):
        raise LoomError(a.path, "summary.resolution", f"must be three integers, got {res!r}; {REBUILD}")
    nx, ny, nz = res
    xyz = a.need("density", "resolution")[::-1]
    a.same("resolution", [nx, ny, nz], xyz, f"array density holds {xyz} (x, y, z) voxels")
    for name, want in (("density", [nz, ny, nx]), ("roughness", [nz, ny, nx]), ("direction", [nz, ny, nx, 3]),
                       ("albedo", [nz, ny, nx, 3])):
        a.shaped(name, want, "resolution")


def _tables(a: _Arrays) -> None:
    Y = a.rows("yarn_type", "yarns")
    a.same("yarns", a.value("yarns"), Y, f"array yarn_type holds {Y}")


def _render(a: _Arrays) -> None:
    H, W = a.value("height"), a.value("width")
    h, w = a.dim("image", 0, "height"), a.dim("image", 1, "width")
    a.same("height", H, h, f"array image has {h} rows")
    a.same("width", W, w, f"array image has {w} columns")


CHECKS = {"tiling": _tiling, "svf": _svf, "iirtf": _iirtf, "btf": _btf, "yarns": _yarns, "fibers": _fibers,
          "grid": _grid, "tables": _tables, "render": _render}


def check_summary(path, kind: str, summary: dict, arrays: dict) -> None:
    """Refuse (LoomError naming ``summary.<key>``) an artifact of ``kind`` whose summary's counts, shapes
    or orders disagree with its arrays' shapes ``arrays`` ({name: {"dtype", "shape"}}); the schema has
    been checked already (the summary's keys and types are there)."""
    check = CHECKS.get(kind)
    if check is None:
        return
    a = _Arrays(Path(path), kind, summary, arrays)
    try:
        check(a)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:
        raise LoomError(path, "summary", f"cannot be checked against the arrays ({type(e).__name__}: {e}); "
                        f"{REBUILD}") from None
