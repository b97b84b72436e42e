"""A yarn's colour means the same in every method: from the colour a user asks for to the fibres' BCSDF.

Convention
----------
``yarns.<group>.color`` (or a WIF draft's colour, or the yarn preset's ``albedo``) is what cloth of that
yarn *shows* under white diffuse light: the mean linear-RGB radiance of a dense, flat cloth woven of it
(``flat_cloth``: two crossed layers of yarns 2.5 radii apart), seen from above in a uniform white
environment of radiance 1 -- its multiple-scattering albedo, every bounce counted. A fibre's own
parameters are much darker than that, and non-linearly so: light in cloth meets tens of fibres before it
leaves, so a fibre that keeps 90 % of what reaches it gives a cloth that shows about a fifth (the
cotton BCSDF on cotton1 yarns). Multiplying the colour into the fibre parameters (the former ``tint``)
therefore made a red knit near-black. Cloth, not a lone yarn, because a lone yarn returns what it transmits to the sky
behind it: the same fibres show 0.80 / 0.22 / 0.15 as a lone yarn and 0.64 / 0.13 / 0.085 as the chart's
swatch (``make gallery``); an open fabric (a knit, a voile) shows its colour a little brighter than asked.

Each method derives its own parameters from that colour:

- ``fiberpath``, ``volpath`` (BCSDF phase function) and the ``prt`` / ``btf`` acquisitions, which scatter
  by the fibres' BCSDF (Khungurn et al. 2015): the transmission colour C_TT per channel from the yarn's
  albedo curve (below); the surface reflection is the fibre material's, uncoloured: C_R = the dielectric
  reflectance ((n - 1) / (n + 1))^2 of the preset's refractive index ``ior`` (default 1.55: 0.047). A dye
  colours what passes through a fibre, not the reflection at its surface, and a dielectric fibre reflects
  4-6 % at normal incidence; the tabulated presets' C_R (0.04-0.99, coloured) are fits to one dyed fabric
  each and would put a floor of up to 35 % under every colour (polyester's 0.7: no dark polyester at all).
  The preset's lobe widths are kept. ``--set tint=none`` renders the presets as tabulated (their C_R and
  C_TT, the yarn colour ignored).
- ``volpath`` with ``phase=microflake``: the dyed BCSDF's mean single-scattering albedo.
- ``bysdf``: its body colours by a colour curve of its own, the same canonical cloth rendered by ``bysdf``
  (``pipeline.renderers.bysdf``, Colour), kept in the same store (``stored_curve``).

The albedo curve (in the manner of Chiang et al. 2016, who map a hair colour to absorption through
simulated hair volumes)
----------------------------------------------------------------------------------------------------
For one BCSDF (its widths and reflection) and one yarn geometry (the yarn preset with its fibre
radius, i.e. fibres across the yarn, plies, packing, twist and flyaways), A(x) is the albedo defined
above of the canonical cloth whose fibres have C_TT = x, measured on ``CURVE_NODES`` values of x by an
analog random walk through the explicit fibres (``stages.render.integrators.albedo_walk``: the BCSDF's
exact albedo as survival probability and its lobes sampled exactly, so every path scores 0 or 1 -- the
path tracer's weights are heavy-tailed in dense cloth, see that module). A is increasing in x, A(1) = 1
exactly (no absorption: the white furnace), A(0) = what the reflection alone returns. The inverse, per
channel: ``C_TT = A^-1(colour)``, piecewise linear between (s, log A), s = sqrt(1 - x): diffusion's
albedo falls nearly exponentially with the square root of the absorption, so log A is nearly linear in s
(cotton on cotton1: A = 1, 0.69, 0.39, 0.24, 0.16 at s = 0, 1/11, 2/11, ...), except near s = 0, where
A falls faster still, and near s = 1 (the darkest colours), where the reflection's floor bends it: the
nodes are dense at both ends (``curve_nodes``: with 16 nodes dense near s = 0 only, silk's 0.04 black came
out 0.035; the round trip in tests/render/test_yarn_colour.py bounds the interpolation's error); colours
below A(0) (darker than the
reflection alone allows) get C_TT = 0 and are reported. The yarn geometry is the scene's yarn type
(``yarns.<group>``: preset, fibre radius), scale-free (a yarn scaled by S with its fibres is the same
yarn); the fabric's own weave is not part of it (measured against the chart's swatch in
docs/methods/fiberpath.md, *Colour*).

Curves are computed once per (BCSDF, geometry) and kept: bundled presets' pairs in
``data/bcsdf/albedo_curves.json`` (``make albedo-curves`` writes it), others in the user cache
(``LOOMLIGHT_CACHE_DIR``, default ``~/.cache/loomlight``), each a few seconds on first use. The same key
gives the same curve bytes, so a render does not depend on where its curve came from.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

BUNDLED_CURVES = Path(__file__).resolve().parents[1] / "data" / "bcsdf" / "albedo_curves.json"
CURVE_VERSION = 4            # part of every key: change it when the measurement changes
ALBEDO_FLOOR = 1e-6          # log A is interpolated: albedos below this count as this
CURVE_NODES = 20             # x nodes at s = sqrt(1 - x) = smoothstep(k / 19): dense near x = 1 and x = 0
CURVE_RAYS = 32768           # camera rays per node (standard error <= 0.5 / sqrt(rays) = 0.28 %)
CURVE_MAX_EVENTS = 1_000_000  # fibre events per path (a non-absorbing path always escapes long before)
CURVE_SPACING = 0.05         # realization step along the yarns, in yarn radii
CLOTH_YARNS = 7              # yarns per layer of the canonical cloth (``flat_cloth``)
CLOTH_SPACING = 2.5          # their spacing, in yarn radii (a dense weave: 0.5 radii between yarns)
CLOTH_RAY_START = 10.0       # camera rays start at this height (yarn radii) above the cloth
CURVE_SEED = 1
KEY_DIGITS = 9               # geometry values rounded to 9 significant digits in the key and the render
DEFAULT_IOR = 1.55           # textile fibres' refractive index when a preset gives none (cellulose, keratin, fibroin)
GEOMETRY_KEYS = ("ply_num", "fiber_num", "yarn_radius", "yarn_alpha", "yarn_clock_wise", "alpha", "fiber_clock_wise",
                 "ellipse_short", "ellipse_long", "epsilon", "beta", "R_max", "s_i", "rho_min", "rho_max",
                 "flyaway_hair_density", "flyaway_hair_ze", "flyaway_hair_r0", "flyaway_hair_re", "flyaway_hair_pe",
                 "flyaway_loop_density", "flyaway_loop_r1", "use_migration", "use_flyaways", "fiber_radius")


class AlbedoCurve(NamedTuple):
    """A(x) at the nodes x (increasing); ``albedo`` is (nodes, ) mean over the yarn's pixels."""
    x: np.ndarray
    albedo: np.ndarray

    def _table(self):
        """(s, log A): s = sqrt(1 - x) increasing, log A non-increasing (noise made monotone)."""
        s = np.sqrt(np.maximum(1.0 - self.x, 0.0))[::-1]
        a = np.minimum.accumulate(np.maximum(self.albedo[::-1], ALBEDO_FLOOR))
        return s, np.log(a)

    def invert(self, colour) -> tuple[np.ndarray, np.ndarray]:
        """(C_TT per channel, reachable per channel) for a yarn colour: A^-1, piecewise linear in
        (sqrt(1 - x), log A)."""
        s, la = self._table()
        c = np.asarray(colour, np.float64)
        reach = c >= np.exp(la[-1])     # above A(1) (1: the white furnace) is C_TT = 1, not an error
        s_of = np.interp(np.log(np.maximum(c, ALBEDO_FLOOR)), la[::-1], s[::-1])
        return np.clip(1.0 - s_of * s_of, 0.0, 1.0), reach

    def at(self, x) -> np.ndarray:
        """A at C_TT = x, the inverse's own interpolation."""
        s, la = self._table()
        return np.exp(np.interp(np.sqrt(np.maximum(1.0 - np.asarray(x, np.float64), 0.0)), s, la))


def curve_nodes() -> np.ndarray:
    t = np.linspace(0.0, 1.0, CURVE_NODES)
    s = t * t * (3.0 - 2.0 * t)
    return np.sort(1.0 - s * s)


def dielectric_reflectance(ior: float) -> float:
    """Fresnel reflectance at normal incidence of a dielectric of refractive index ``ior`` in air."""
    return ((float(ior) - 1.0) / (float(ior) + 1.0)) ** 2


_REFLECTION: dict = {}


def preset_reflection(name: str) -> float:
    """The dyed fibres' surface reflection C_R of BCSDF preset ``name`` (a bundled name or a .toml path):
    ``dielectric_reflectance`` of its ``ior`` (``DEFAULT_IOR`` when it gives none or is unnamed)."""
    if name not in _REFLECTION:
        ior = DEFAULT_IOR
        if name:
            from .bcsdf_presets import read_bcsdf_preset

            ior = read_bcsdf_preset(name)[1].get("ior", DEFAULT_IOR)
        _REFLECTION[name] = dielectric_reflectance(ior)
    return _REFLECTION[name]


def dyed_bcsdf(p, c_tt, reflection: float) -> np.ndarray:
    """The packed BCSDF of a dyed fibre: C_R = ``reflection`` in every channel (uncoloured), C_TT per
    channel, the widths of ``p``; ``c_tt`` (..., 3) gives (..., BCSDF_SIZE), in C order (a copy of the broadcast
    rows keeps their layout, Fortran order, and numba compiles a kernel again for each layout)."""
    from stages.core.shading.bcsdf import C_R, C_TT

    c = np.clip(np.asarray(c_tt, np.float64), 0.0, 1.0)
    q = np.array(np.broadcast_to(np.asarray(p, np.float64), c.shape[:-1] + (len(p),)), order="C")
    q[..., C_R:C_R + 3] = reflection
    q[..., C_TT:C_TT + 3] = c
    return q


def _round(v):
    if isinstance(v, (list, tuple)):
        return [_round(u) for u in v]
    v = float(v)
    return float(f"{v:.{KEY_DIGITS}g}")


def unit_geometry(preset: dict) -> dict:
    """The yarn's geometry scaled to yarn radius 1, rounded to ``KEY_DIGITS`` (scale-free: the key)."""
    from .presets import scale_preset

    d = scale_preset({**preset}, 1.0)
    return {k: _round(d[k]) for k in GEOMETRY_KEYS if k in d}


def curve_key(p, reflection: float, geometry: dict) -> str:
    from stages.core.shading.bcsdf import BETA_R, BETA_TT, GAMMA_TT

    q = np.asarray(p, np.float64)
    doc = {"version": CURVE_VERSION, "rays": CURVE_RAYS, "nodes": CURVE_NODES, "c_r": _round(reflection),
           "widths": _round([q[BETA_R], q[BETA_TT], q[GAMMA_TT]]), "geometry": geometry}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:20]


def flat_cloth_curves(geometry: dict):
    """(Curves, packed yarn type (1, P)) of the canonical cloth of a yarn of radius 1 (module doc): two crossed
    layers of ``CLOTH_YARNS`` straight parallel yarns, ``CLOTH_SPACING`` apart, along x at z = +1 and along y
    at z = -1 (the layers touch), every yarn of the one type ``geometry``."""
    from stages.ingest.spline_process import curves_from_arrays, process_curves

    from .presets import DEFAULT_PRESET, DEFAULTS, load_preset, pack

    # keys outside the geometry (the fitted sample's extents, albedo) are not read by realize
    geometry = {**load_preset(DEFAULT_PRESET), **DEFAULTS, **geometry}
    n, half = 17, 0.5 * (CLOTH_YARNS * CLOTH_SPACING + 4.0)
    along = np.linspace(-half, half, n)
    curves = []
    for k in range(CLOTH_YARNS):
        across = (k - 0.5 * (CLOTH_YARNS - 1)) * CLOTH_SPACING
        curves.append(np.stack([along, np.full(n, across), np.full(n, 1.0)], -1))
        curves.append(np.stack([np.full(n, across), along, np.full(n, -1.0)], -1))
    pts = np.concatenate(curves)
    off = np.arange(0, len(pts) + 1, n, dtype=np.int64)
    Y = len(curves)
    closed = np.zeros(Y, bool)
    rad = np.ones(Y)
    cv = curves_from_arrays(pts, off, closed, rad, process_curves(pts, off, closed, rad))
    return cv, pack(dict(geometry))[None, :]


def flat_cloth(geometry: dict):
    """(points, offsets, radii) of the fibres of the canonical cloth (``flat_cloth_curves``), realized by the
    procedural model."""
    from stages.procedural.realize import realize_fill, realize_plan
    from stages.procedural.tables import build_tables

    cv, tparams = flat_cloth_curves(geometry)
    Y = len(cv.offsets) - 1
    tab, _ = build_tables(cv, tparams, np.zeros(Y, np.int32), np.ones((Y, 3)), CURVE_SEED)
    yarn, ply, idx, kind, a0, a1, hz1, hze, nv = realize_plan(tab, cv.curve_length, CURVE_SPACING)
    offsets = np.zeros(len(nv) + 1, np.int64)
    np.cumsum(nv, out=offsets[1:])
    points = np.zeros((offsets[-1], 3))
    radius = np.zeros(offsets[-1])
    realize_fill(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, offsets, points, radius)
    return points, offsets, radius


def measure_curve(p, reflection: float, geometry: dict, rays: int = CURVE_RAYS) -> AlbedoCurve:
    """Measure the albedo curve (module doc) by the analog walk of ``stages.render.integrators.albedo_walk``
    on the canonical cloth of the yarn (``flat_cloth``): ``CURVE_NODES`` values of C_TT, ``rays`` camera
    rays each, straight down onto the middle ``CLOTH_SPACING`` x ``CLOTH_SPACING`` square."""
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.render.integrators.albedo_walk import yarn_albedo

    from .render_setup import SELF_WINDOW, ray_eps

    pts, offs, rad = flat_cloth(geometry)
    bvh, _ = build_fiber_bvh(pts, offs, rad)
    xs = curve_nodes()
    mats = dyed_bcsdf(p, np.repeat(xs[:, None], 3, axis=1), reflection)
    s = CLOTH_SPACING
    albedo, _, _ = yarn_albedo(bvh, mats, np.array([-0.5 * s, -0.5 * s, CLOTH_RAY_START]), np.array([s, 0.0, 0.0]),
                               np.array([0.0, s, 0.0]), np.array([0.0, 0.0, -1.0]), rays, CURVE_SEED,
                               ray_eps(pts.min(axis=0), pts.max(axis=0)), SELF_WINDOW, CURVE_MAX_EVENTS)
    return AlbedoCurve(xs, albedo)


def user_cache() -> Path:
    root = os.environ.get("LOOMLIGHT_CACHE_DIR")
    return (Path(root) if root else Path.home() / ".cache" / "loomlight") / "albedo_curves.json"


def _read(path: Path) -> dict:
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return doc.get("curves", {}) if isinstance(doc, dict) else {}


def write_curves(path: Path, curves: dict) -> None:
    """Write (atomically) a curves file: {key: {"x": [...], "albedo": [...], "about": {...}}}."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps({"version": CURVE_VERSION, "curves": dict(sorted(curves.items()))}, indent=1) + "\n")
    os.replace(tmp, path)


_MEMO: dict = {}


def stored_curve(key: str, measure, about: dict | None = None) -> AlbedoCurve:
    """The albedo curve of ``key``: memoised, then the bundled file, then the user cache, else ``measure()``
    (an ``AlbedoCurve``; kept in the user cache). ``about`` names it in the files and the progress line."""
    if key in _MEMO:
        return _MEMO[key]
    entry = _read(BUNDLED_CURVES).get(key) or _read(user_cache()).get(key)
    if entry is None:
        what = " on ".join(v for v in (about or {}).values() if v) or "a yarn"
        from .progress import begin, end
        w = begin(f"albedo curve of {what} (once; kept in {user_cache()})")
        try:
            c = measure()
        finally:
            end(w)
        entry = {"x": c.x.tolist(), "albedo": c.albedo.tolist(), "about": about or {}}
        try:
            cache = _read(user_cache())
            cache[key] = entry
            write_curves(user_cache(), cache)
        except OSError:
            pass                    # a read-only home: measured again next time, same bytes
    curve = AlbedoCurve(np.asarray(entry["x"], np.float64), np.asarray(entry["albedo"], np.float64))
    _MEMO[key] = curve
    return curve


def albedo_curve(p, reflection: float, preset: dict, about: dict | None = None) -> AlbedoCurve:
    """The albedo curve of BCSDF ``p`` with surface reflection ``reflection`` on yarn ``preset`` (a resolved
    preset dict), through ``stored_curve``."""
    geometry = unit_geometry(preset)
    return stored_curve(curve_key(p, reflection, geometry), lambda: measure_curve(p, reflection, geometry), about)


class Dyer:
    """Dyed BCSDF rows for a scene's yarns: ``row(p, colour, group)``, the curve memoised per BCSDF and
    group; ``report()`` warns once per (BCSDF, group) whose colours were darker than it can show."""

    def __init__(self, scene):
        self.scene = scene
        self._geometry: dict = {}
        self._curves: dict = {}
        self.unreachable: dict = {}

    def geometry(self, group: str) -> dict:
        """The resolved yarn preset of ``group``, a yarn type's label (``pipeline.scene``: ``yarns.<group>``,
        else ``default``; a group its fabric does not describe takes the fabric's one described group when
        there is one)."""
        if group not in self._geometry:
            from .presets import resolve_yarn_types
            from .scene import merged_yarn_type

            t = {}
            if self.scene is not None:
                yarns, g = self.scene.yarns_of(group)
                t = merged_yarn_type(yarns, g)
                described = [k for k in yarns if k != "default"]
                if g not in yarns and "default" not in yarns and len(described) == 1:
                    t = merged_yarn_type(yarns, described[0])
            t = {k: v for k, v in t.items() if k not in ("color", "bcsdf")}
            self._geometry[group] = resolve_yarn_types([t], [0.0], file=getattr(self.scene, "path", None))[0]
        return self._geometry[group]

    def curve(self, p, group: str, bcsdf_name: str = "") -> AlbedoCurve:
        k = (np.asarray(p, np.float64).tobytes(), group, bcsdf_name)
        if k not in self._curves:
            geo = self.geometry(group)
            self._curves[k] = albedo_curve(p, preset_reflection(bcsdf_name), geo,
                                           {"bcsdf": Path(bcsdf_name).stem, "yarn": geo.get("name", "")})
        return self._curves[k]

    def row(self, p, colour, group: str, bcsdf_name: str = "") -> np.ndarray:
        curve = self.curve(p, group, bcsdf_name)
        c_tt, reach = curve.invert(colour)
        if not np.all(reach):
            self.unreachable.setdefault((Path(bcsdf_name).stem, group), float(curve.albedo[0]))
        return dyed_bcsdf(p, c_tt, preset_reflection(bcsdf_name))

    def report(self) -> None:
        from .progress import warn

        for (name, group), floor in sorted(self.unreachable.items()):
            where = self.scene.type_place(group) if self.scene is not None else f"yarns.{group}"
            warn(f"{where}: a colour below {floor:.3f} in some channel is darker than the {name or 'BCSDF'} "
                 f"fibres' uncoloured surface reflection lets a yarn be; rendered at that floor")
