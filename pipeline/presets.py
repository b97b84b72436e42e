"""Procedural yarn presets (``data/yarns/<name>.toml``) and the yarn types of a fabric.

Keys (Luan et al. 2017 §3.2; names of the original fitting tool; lengths in centimetres):
  ply_num, fiber_num          plies per yarn, fibres per ply (>= 1)
  yarn_radius                 ply centres sit on a circle of radius yarn_radius / 2 (0 for one ply)
  yarn_alpha, alpha           pitch (length per turn) of the plies around the yarn axis / of the fibres
                              around their ply centre; yarn_clock_wise, fiber_clock_wise: 1 turns the
                              other way (negative angle per length)
  ellipse_short, ellipse_long ply cross-section half axes, along / across the axis -> ply direction
  epsilon, beta, R_max        p(R) = (1 - 2 eps) ((e - e^(R/R_max)) / (e - 1))^beta + eps, by rejection
  s_i, rho_min, rho_max       migration R(z) = R_j [rho_min + (rho_max - rho_min)/2 (cos(s 2 pi z/alpha + theta0) + 1)]
  flyaway_hair_density        hairs per unit length per ply; flyaway_hair_ze/r0/re/pe: [mu, sigma] of a hair's
                              z extent, start radius, radius extent, azimuth extent (drawn with 0.75 sigma)
  flyaway_loop_density        loops per unit length per ply; flyaway_loop_r1: [mu, sigma] of a loop's maximal
                              radius (drawn with 0.5 sigma; kept where > 1.05 x the fibre's radius there)
  use_migration, use_flyaways 0/1 switches; aabb_*, z_step_*: the fitted sample's extent (informative)
  packing_fraction            fraction of a ply's cross-section its fibres fill (default ``PACKING_FRACTION``)
  fiber_radius                default sqrt(packing_fraction e_long e_short / fiber_num): the radius at which the
                              fitted fibre count fills that fraction of the ply's elliptical cross-section
  density                     volpath's extinction inside a fibre, per unit length; default ``fibre_density``
                              = FIBRE_OPTICAL_DEPTH / (2 fiber_radius)
  albedo (RGB), roughness     the fibres' colour when a scene names none, the SGGX roughness: loomlight
                              defaults (not fitted)

Same fibres, same optics. The fitted presets give fibre counts and ply shapes from CT-scanned yarns
but no fibre radius; at the radii of real fibres (5-10 um) those counts fill 1.5-9 % of a ply, and
an explicit-fibre render of such a yarn is see-through while its volume (at any density a volume
renders solid) is not. loomlight therefore sizes fibres so the plies are packed as real staple
yarns are (``PACKING_FRACTION`` = 0.5; ring-spun yarns measure about 0.4-0.6), and volpath's
medium, which is non-zero only inside those fibres (Luan et al. 2017 §4), stands for them as a cloud of
opaque cylinders: a fibre of radius r intercepts every ray that crosses it, projecting 2 r per unit
length, which a medium fibre does only in the limit of infinite density. Its density is set by the
optical depth ``FIBRE_OPTICAL_DEPTH`` (kappa) across a fibre's diameter, den = kappa / (2 r): a ray
crossing the fibre at a uniformly random offset is scattered with probability
P(kappa) = mean over offsets u of 1 - exp(-kappa sqrt(1 - u^2)) = 0.956 at kappa = 5, so the volume
extinguishes 0.956 of the fibres' projected area per volume (kappa = 1.27, den = 2 / (pi r), would
only match the projected area if the fibres were spread evenly, and gives P = 0.62). Delta tracking
costs a lookup per 1 / den of path inside fibre-occupied majorant cells, so kappa is a compromise:
kappa = 5 costs about what the former fixed density of 1000 per cm did. The volume's scattering is the
fibres' BCSDF (``stages.render.integrators.volpath``, ``pipeline.renderers.volpath``).

Scaling to a yarn radius R (``scale_preset``) is a similarity transform with factor
S = R / yarn_radius: every length is multiplied by S (yarn_radius, ellipse axes, both pitches,
hair z extent, start radius and radius extent, loop radius, fibre radius) and every per-length
density divided by S (counts per yarn twist stay the same); angles (azimuth extent) and the unit-disc
parameters (epsilon, beta, R_max, rho_*) are unchanged. A scaled yarn is the fitted yarn magnified.

The yarn type of a yarn: the scene's [yarns.<group>] table (preset, radius, color, fiber_radius,
density, roughness) as recorded in the yarns artifact's ``summary.yarn_types``; on the command
line ``--preset NAME`` and ``--radius R`` override every type. Without a radius a type is scaled to
the median radius of its curves. A type without a preset uses ``DEFAULT_PRESET``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import LoomError, check_name
from .schemas import validate
from .toml_file import read_toml

PRESET_DIR = Path(__file__).resolve().parents[1] / "data" / "yarns"
DEFAULT_PRESET = "cotton1"
LENGTH_KEYS = ("yarn_radius", "ellipse_long", "ellipse_short", "yarn_alpha", "alpha", "fiber_radius")
NORMAL_LENGTH_KEYS = ("flyaway_hair_ze", "flyaway_hair_r0", "flyaway_hair_re", "flyaway_loop_r1")
DENSITY_KEYS = ("flyaway_hair_density", "flyaway_loop_density")
DEFAULTS = {"R_max": 1.0, "rho_max": 1.0, "use_migration": 1, "use_flyaways": 1}
MAX_RATIO = 1e3   # lengths within 1/MAX_RATIO..MAX_RATIO yarn radii (check_proportions)
PACKING_FRACTION = 0.5
FIBRE_OPTICAL_DEPTH = 5.0  # kappa: a medium fibre's optical depth across its diameter (module doc)


def packed_fibre_radius(d: dict, packing: float | None = None) -> float:
    """The fibre radius at which ``fiber_num`` fibres fill ``packing`` of a ply's elliptical cross-section."""
    f = float(packing if packing is not None else d.get("packing_fraction", PACKING_FRACTION))
    return float(np.sqrt(f * d["ellipse_long"] * d["ellipse_short"] / d["fiber_num"]))


def fibre_density(fiber_radius: float) -> float:
    """volpath's extinction inside a fibre, kappa / (2 r): a medium fibre of optical depth kappa across
    its diameter, nearly as opaque as the explicit fibre it stands for (module doc)."""
    return FIBRE_OPTICAL_DEPTH / (2.0 * float(fiber_radius))


def list_presets() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.toml"))


def check_preset(d: dict, file, place_prefix: str = "") -> dict:
    """Schema and cross-key checks; raises LoomError naming the parameter."""
    validate(d, "yarn-preset", file, prefix=place_prefix)
    d = {**DEFAULTS, **d}
    if d["rho_min"] > d["rho_max"]:
        raise LoomError(file, f"{place_prefix}rho_min", f"rho_min ({d['rho_min']}) exceeds rho_max ({d['rho_max']})")
    if "fiber_radius" not in d:
        d["fiber_radius"] = packed_fibre_radius(d)
    check_proportions(d, file, place_prefix)
    return d


def check_proportions(d: dict, file, place_prefix: str = "") -> None:
    """Pitches, ply axes and fibre radius within 1/MAX_RATIO..MAX_RATIO yarn radii, flyaway lengths and
    per-length densities at most MAX_RATIO yarn radii (per yarn radius): beyond, a yarn twists or fills
    faster than float64 positions along it resolve, and the tables would be noise."""
    R = d["yarn_radius"]
    for k in ("yarn_alpha", "alpha", "ellipse_long", "ellipse_short", "fiber_radius"):
        if not R / MAX_RATIO <= d[k] <= R * MAX_RATIO:
            raise LoomError(file, f"{place_prefix}{k}", f"{d[k]:g} is not within 1e-3 to 1e3 times yarn_radius ({R:g})")
    for k in NORMAL_LENGTH_KEYS:
        if max(abs(d[k][0]), d[k][1]) > R * MAX_RATIO:
            raise LoomError(file, f"{place_prefix}{k}", f"{d[k]} exceeds 1e3 times yarn_radius ({R:g})")
    for k in DENSITY_KEYS:
        if d[k] * R > MAX_RATIO:
            raise LoomError(file, f"{place_prefix}{k}", f"{d[k]:g} per unit length exceeds 1e3 per yarn_radius ({R:g})")


def check_preset_name(name: str, file=None, place: str = "--preset") -> None:
    """``name`` is a bundled preset (or a preset file's path without ``.toml``), else an error at ``place``
    of ``file`` listing the known names and the nearest one."""
    if not (PRESET_DIR / f"{name}.toml").is_file():
        check_name(name, list_presets(), file, place, "preset")


def load_preset(name: str, file=None, place: str = "--preset") -> dict:
    """A bundled preset by name, checked; an unknown name is an error at ``place`` of ``file`` (the
    command-line option ``--preset`` when ``file`` is None), with the known names."""
    check_preset_name(name, file, place)
    path = PRESET_DIR / f"{name}.toml"  # a path without .toml also works (PRESET_DIR / absolute = absolute)
    d = read_toml(path, what="yarn preset")
    return check_preset(d, path)


def scale_preset(d: dict, radius: float, file=None, place: str = "--radius") -> dict:
    """The preset magnified to yarn radius ``radius`` (see the module doc for the rule); a radius that is
    not positive is an error at ``place`` of ``file``."""
    if not radius > 0:
        raise LoomError(file, place, f"yarn radius must be positive, got {radius}")
    S = float(radius) / float(d["yarn_radius"])
    out = dict(d)
    for k in LENGTH_KEYS:
        out[k] = d[k] * S
    for k in NORMAL_LENGTH_KEYS:
        out[k] = [d[k][0] * S, d[k][1] * S]
    for k in DENSITY_KEYS:
        out[k] = d[k] / S
    out["scale"] = S
    return out


def apply_overrides(d: dict, yt: dict, file=None, place: str = "yarns") -> dict:
    """Scene yarn-type overrides (packing_fraction, fiber_radius, density, roughness, color -> albedo),
    checked; the density defaults to ``fibre_density`` of the final fibre radius."""
    out = dict(d)
    if "packing_fraction" in yt and "fiber_radius" not in yt:
        out["fiber_radius"] = packed_fibre_radius(out, yt["packing_fraction"])
    for k in ("fiber_radius", "density", "roughness"):
        if k in yt:
            out[k] = float(yt[k])
    if "color" in yt:
        out["albedo"] = [float(x) for x in yt["color"]]
    if not out["fiber_radius"] > 0:
        raise LoomError(file, f"{place}.fiber_radius", "fibre radius must be positive")
    if "density" not in out:
        out["density"] = fibre_density(out["fiber_radius"])
    if out["density"] < 0:
        raise LoomError(file, f"{place}.density", "density must not be negative")
    return out


def pack(d: dict) -> np.ndarray:
    """The float64 parameter vector of stages.core.yarn.model (bounds filled in)."""
    from stages.core.yarn import model as M

    tp = np.zeros(M.NPARAM)
    P = int(d["ply_num"])
    tp[M.PLY_NUM] = P
    tp[M.FIBER_NUM] = int(d["fiber_num"])
    tp[M.PLY_RADIUS] = 0.5 * d["yarn_radius"] if P > 1 else 0.0
    tp[M.YARN_RADIUS] = d["yarn_radius"]
    tp[M.YARN_ALPHA] = d["yarn_alpha"]
    tp[M.YARN_SGN] = -1.0 if d["yarn_clock_wise"] else 1.0
    tp[M.ALPHA] = d["alpha"]
    tp[M.FIBER_SGN] = -1.0 if d["fiber_clock_wise"] else 1.0
    tp[M.E_LONG] = d["ellipse_long"]
    tp[M.E_SHORT] = d["ellipse_short"]
    tp[M.EPSILON] = d["epsilon"]
    tp[M.BETA] = d["beta"]
    tp[M.R_MAX] = d.get("R_max", 1.0)
    tp[M.RHO_MIN] = d["rho_min"]
    tp[M.RHO_MAX] = d.get("rho_max", 1.0)
    tp[M.S_MIG] = d["s_i"]
    tp[M.HAIR_DENSITY] = d["flyaway_hair_density"]
    tp[M.LOOP_DENSITY] = d["flyaway_loop_density"]
    for (mu, sig), key, f in ((M.ZE_MU, M.ZE_SIG), "flyaway_hair_ze", 0.75), \
            ((M.R0_MU, M.R0_SIG), "flyaway_hair_r0", 0.75), \
            ((M.RE_MU, M.RE_SIG), "flyaway_hair_re", 0.75), ((M.PE_MU, M.PE_SIG), "flyaway_hair_pe", 0.75), \
            ((M.R1_MU, M.R1_SIG), "flyaway_loop_r1", 0.5):
        tp[mu] = d[key][0]
        tp[sig] = d[key][1] * f
    tp[M.FIBER_RADIUS] = d["fiber_radius"]
    tp[M.ALB_R:M.ALB_B + 1] = d["albedo"]
    tp[M.DENSITY] = d["density"] if "density" in d else fibre_density(d["fiber_radius"])
    tp[M.ROUGHNESS] = d["roughness"]
    tp[M.USE_MIGRATION] = float(d.get("use_migration", 1))
    tp[M.USE_FLYAWAYS] = float(d.get("use_flyaways", 1))
    # loops: each migration cycle (length alpha / s) mutated with p = density * alpha / (N s)
    tp[M.P_LOOP] = min(1.0, d["flyaway_loop_density"] * d["alpha"] / (d["fiber_num"] * d["s_i"]))
    tp[M.U_MAX] = M.loop_bound(tp)
    tp[M.HAIR_RMAX] = M.hair_radius_bound(tp)
    return tp


def resolve_yarn_types(yarn_types: list[dict], type_radius: list[float], preset: str | None = None,
                       radius: float | None = None, file=None) -> list[dict]:
    """Checked, scaled preset dicts, one per yarn type.

    yarn_types: the scene's yarn-type tables (artifact ``summary.yarn_types``), type_radius: the median
    curve radius of each type; ``preset`` / ``radius`` (command line) override every type."""
    if radius is not None and not radius > 0:
        raise LoomError(file, "--radius", f"yarn radius must be positive, got {radius}")
    out = []
    for i, yt in enumerate(yarn_types or [{}]):
        yt = dict(yt or {})
        name = preset or yt.get("preset") or DEFAULT_PRESET
        d = load_preset(name) if preset else load_preset(name, file, f"yarn_types[{i}].preset")
        R = radius or yt.get("radius") or (type_radius[i] if i < len(type_radius) and type_radius[i] > 0 else None)
        if R is not None:
            d = scale_preset(d, float(R))
        else:
            d["scale"] = 1.0
        d = apply_overrides(d, yt, file, place=f"yarn_types[{i}]")
        check_proportions(d, file, f"yarn_types[{i}].")
        d["name"] = name
        out.append(d)
    return out
