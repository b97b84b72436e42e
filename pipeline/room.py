"""The room: a Sponza-class scene made by code, no external assets (``loomlight room -o DIR``).

Luan, Zhao, Bala 2017's headline (Fig. 1, Table 1) is Crytek's Sponza dressed in 12 procedural textiles:
33,302 yarns, 8.1 M fibres, 867 GB if realized. ``write_room(out_dir)`` writes a scene of that class from
boxes and generated fabrics: a living room 5 m x 4 m x 2.7 m (centimetres, z up) with two windows in its
back wall, seen from its open front, and in it

- four **curtains** (woven, pleated, stood upright: the hanging cloth of ``pleats``), two per window;
- a **tablecloth** draped over the table (an OBJ drape onto ``tablecloth.obj``, a top and two drops whose
  texture coordinates keep lengths);
- three **cushions** on the sofa (knits: stockinette, garter, 1x1 rib; OBJ drapes onto cushion height
  fields, leaning against the sofa's back), a **throw** over the sofa's arm roll (a cylinder drape);
- a **loop-pile rug** (its tufts written as a BCC curve file, one short U-shaped yarn per tuft, which is
  where most of the scene's yarns are, as in a real tufted rug), on a rug backing;
- a **wall hanging** between the windows (the bundled WIF draft ``2229.wif``, tiled);

eleven textiles of woven drafts (plain, twill, satin, a WIF draft), knits and a pile, from eight
yarn presets; meshes for the floor, walls, ceiling, sofa, table, shelf and rug backing (Lambertian), a
glass vase (rough dielectric), a ceiling lamp and two window panes that emit (area lights: the daylight;
they would block a sun, so there is none) and a sky through the open front. Everything is made by this
module: the scene TOML, the OBJ meshes, the pile's curve file and a copy of the draft (``RoomFiles``).

The scene's size: ``RoomFiles.yarns`` counts the yarns per textile from the generator tables (ends +
picks; courses) and the tufts written (a test checks them against ingest); the full realization is
counted by ``loomlight realize``'s estimate, which refuses it with the number (42,752 yarns, 838 GiB at
``scale`` 1). ``scale`` (default 1) multiplies the threads per centimetre of the woven fabrics and knits
and the pile's tufts per square centimetre, the yarns thicker in proportion so the cloth stays closed
(``scale`` 0.1: about a tenth of the yarns, for tests and previews); the geometry stays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .curveset import CurveSet
from .errors import LoomError
from .toml_file import toml_value

ROOM_SIZE = (500.0, 400.0, 270.0)      # cm: x (width), y (depth, the back wall at y = 400), z (height)
WINDOWS = ((80.0, 180.0), (320.0, 420.0))   # x extents of the two windows in the back wall
WINDOW_Z = (80.0, 230.0)                     # their sill and lintel
WALL = 10.0                                   # wall thickness, cm
FRONT = -150.0                                # the open front: floor, ceiling and side walls reach to y = FRONT
PILE_SEED = 11                                # the tufts' random layout
TUFT_JITTER = 0.3                             # a tuft's centre moves up to this many pitches from its grid cell's
TUFT_ARC_POINTS = 7                           # control points on a tuft's half circle
TUFT_LOOP = 1.2                               # a tuft's width, cm
PILE_RADIUS = 0.06                            # the pile yarn's radius, cm
# Crimp, pleats and the tufts' loop keep every yarn's bends wider than its fibres' extent (curvature x extent
# below about 0.4): tighter bends fold the yarn space, and lookups there are inexact and far slower
WOVEN_CRIMP = 0.1                             # the woven fabrics' crimp, in yarn radii
HANGING_CRIMP = 0.04                          # the wall hanging's: its draft's threads are 1.7 radii apart
TABLECLOTH_BEND = 3.0                         # the tablecloth's radius over the table's edges, cm
PLEAT_DEPTH = 4.0                             # the curtains' pleats, peak to trough, cm
HANGING_DRAFT = Path(__file__).resolve().parents[1] / "data" / "drafts" / "2229.wif"   # the wall hanging
HANGING_THREADS = 24                          # ends and picks of one repeat of 2229.wif
CUSHIONS = (("stockinette", "cotton2", (0.80, 0.22, 0.15), 150.0),   # pattern, preset, colour, y of the centre
            ("garter", "silk2", (0.20, 0.35, 0.60), 200.0),
            ("rib1x1", "cotton2", (0.85, 0.70, 0.20), 250.0))
CUSHION_LEAN_DEG = 70.0                       # a cushion's face turned about y from the seat towards the room
SUBTABLES = ("fabric", "generator", "yarns")  # written as [a.b] sections; every other table inline


@dataclass(frozen=True)
class RoomFiles:
    """What ``write_room`` wrote: the scene, its meshes and the pile's curve file, and the yarn counts."""
    scene: Path
    meshes: tuple[Path, ...]
    pile: Path
    yarns: dict            # textile name -> yarns (ends + picks, courses, tufts)

    @property
    def total_yarns(self) -> int:
        return int(sum(self.yarns.values()))


# ------------------------------------------------------------------------------------------------
# meshes
class _Obj:
    """An OBJ under construction: quads and triangles of several parts, optional texture coordinates."""

    def __init__(self, comment: str):
        self.lines = [f"# {ln}" for ln in comment.splitlines()]
        self.nv = 0

    def box(self, lo, hi) -> "_Obj":
        """An axis-aligned box, faces wound counter-clockwise seen from outside."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        b = self.nv + 1
        for z in (z0, z1):
            for y in (y0, y1):
                for x in (x0, x1):
                    self.lines.append(f"v {x:.4f} {y:.4f} {z:.4f}")
        self.nv += 8
        for q in ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)):
            self.lines.append("f " + " ".join(str(b + i) for i in q))
        return self

    def grid(self, P: np.ndarray, UV: np.ndarray | None = None) -> "_Obj":
        """A (n+1) x (m+1) grid of points P[j, i] as quads, with texture coordinates UV[j, i] when given."""
        nj, ni = P.shape[:2]
        if UV is not None and self.nv:
            raise ValueError("a grid with texture coordinates must be its OBJ's first geometry (its v and vt "
                             "lines are numbered alike)")
        b = self.nv + 1
        for p in P.reshape(-1, 3):
            self.lines.append(f"v {p[0]:.5f} {p[1]:.5f} {p[2]:.5f}")
        if UV is not None:
            for t in UV.reshape(-1, 2):
                self.lines.append(f"vt {t[0]:.6f} {t[1]:.6f}")
        self.nv += nj * ni
        for j in range(nj - 1):
            for i in range(ni - 1):
                a = b + j * ni + i
                q = (a, a + 1, a + ni + 1, a + ni)
                if UV is None:
                    self.lines.append("f " + " ".join(str(k) for k in q))
                else:   # vertices and texture coordinates are numbered alike (checked above)
                    self.lines.append("f " + " ".join(f"{k}/{k}" for k in q))
        return self

    def write(self, path: Path) -> Path:
        path.write_text("\n".join(self.lines) + "\n")
        return path


def cushion_grid(size: float, height: float, n: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A cushion's face: z = height (1 - x^4)(1 - y^4) over a size x size square (x, y in [-1, 1]
    across it), centred at the origin, uv in [0, 1]^2 along x and y."""
    t = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(2 * t - 1, 2 * t - 1)
    P = np.stack([0.5 * size * X, 0.5 * size * Y, height * (1 - X ** 4) * (1 - Y ** 4)], axis=-1)
    U, V = np.meshgrid(t, t)
    return P, np.stack([U, V], axis=-1)


def tablecloth_profile(top: float, drop: float, bend: float, n_bend: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The tablecloth's cross-section across x: down-hanging drop, a quarter-circle bend of radius ``bend``
    over the table's edge, the top, the other bend and drop; points (x, z) with z = 0 on the top, and their
    arc length from the first. The top spans x in [-top/2, top/2]."""
    pts = [(-0.5 * top - bend, -drop)]
    pts.append((-0.5 * top - bend, -bend))
    a = np.linspace(math.pi, 0.5 * math.pi, n_bend + 1)[1:]
    pts += [(-0.5 * top + bend * math.cos(t), -bend + bend * math.sin(t)) for t in a]
    pts += [(0.5 * top - bend * math.cos(t), -bend + bend * math.sin(t)) for t in np.linspace(0.5 * math.pi, math.pi,
                                                                                              n_bend + 1)]
    pts.append((0.5 * top + bend, -drop))
    P = np.asarray(pts)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    return P, s


def tablecloth_grid(top: float, depth: float, drop: float, bend: float, n_depth: int = 4):
    """The tablecloth's surface (profile extruded along y over ``depth``), uv = arc length / total along
    the profile, y / depth along it: lengths kept (up to the bends' chords)."""
    P2, s = tablecloth_profile(top, drop, bend)
    y = np.linspace(-0.5 * depth, 0.5 * depth, n_depth + 1)
    P = np.stack([np.broadcast_to(P2[None, :, 0], (len(y), len(s))),
                  np.broadcast_to(y[:, None], (len(y), len(s))),
                  np.broadcast_to(P2[None, :, 1], (len(y), len(s)))], axis=-1)
    UV = np.stack([np.broadcast_to(s[None, :] / s[-1], P.shape[:2]),
                   np.broadcast_to((y[:, None] + 0.5 * depth) / depth, P.shape[:2])], axis=-1)
    return P, UV, float(s[-1])


# ------------------------------------------------------------------------------------------------
# the loop-pile rug
def pile_tufts(width: float, depth: float, pitch: float, height: tuple[float, float], loop: float,
               seed: int = PILE_SEED) -> CurveSet:
    """One U-shaped yarn per tuft on a jittered grid of ``pitch`` over width x depth (centred): up from the
    backing, over a half circle ``loop`` wide, back down, leaning a little; leg heights uniform in ``height``
    and a random turn about z per tuft."""
    rng = np.random.default_rng(seed)
    nx, ny = int(width // pitch), int(depth // pitch)
    gx, gy = np.meshgrid((np.arange(nx) + 0.5) * pitch - 0.5 * width, (np.arange(ny) + 0.5) * pitch - 0.5 * depth)
    n = gx.size
    cx = gx.ravel() + rng.uniform(-TUFT_JITTER, TUFT_JITTER, n) * pitch
    cy = gy.ravel() + rng.uniform(-TUFT_JITTER, TUFT_JITTER, n) * pitch
    h = rng.uniform(height[0], height[1], n)
    turn = rng.uniform(0.0, 2 * math.pi, n)
    lean = rng.normal(0.0, 0.08, (n, 2)) * h[:, None]
    # the U in its own plane (s across, z up): straight legs, a half circle over them of diameter ``loop`` (its
    # bend, 2 / loop, stays below the yarn-space fold of a PILE_RADIUS yarn's extent), control points about a
    # chord of the half circle apart all along (uneven steps make a Catmull-Rom spline bend sharply)
    r = 0.5 * loop
    arc = np.linspace(math.pi, 0.0, TUFT_ARC_POINTS)
    chord = r * math.pi / (TUFT_ARC_POINTS - 1)
    pts = []
    for k in range(n):      # turned about z, leaning in proportion to the height
        up = np.linspace(0.0, 1.0, max(2, math.ceil(h[k] / chord)) + 1)[:-1]     # leg fractions below the arc
        s_ = np.concatenate([np.full(len(up), -r), r * np.cos(arc), np.full(len(up), r)])
        leg = np.concatenate([up, np.ones(TUFT_ARC_POINTS), up[::-1]])
        over = np.concatenate([np.zeros(len(up)), r * np.sin(arc), np.zeros(len(up))])
        c, sn = math.cos(turn[k]), math.sin(turn[k])
        pts.append(np.stack([cx[k] + s_ * c + leg * lean[k, 0], cy[k] + s_ * sn + leg * lean[k, 1],
                             leg * h[k] + over], axis=1))
    return CurveSet(points=pts, closed=[False] * n, group=["other"] * n, curve_type="catmull-rom",
                    source_format="bcc")


# ------------------------------------------------------------------------------------------------
# the scene file
def _table(lines: list, header: str, tbl: dict) -> None:
    """``[header]`` with ``tbl``'s plain keys, then its sub-tables as ``[header.key]``."""
    lines.append(f"[{header}]" if not header.startswith("[") else header)
    name = header.strip("[]")
    subs = []
    for k, v in tbl.items():
        if k in SUBTABLES and isinstance(v, dict):
            subs.append((k, v))
        else:
            lines.append(f"{k} = {toml_value(v, bare_keys=True)}")
    for k, v in subs:
        lines.append("")
        _table(lines, f"[{name}.{k}]", v)


def _woven(pattern: str, width: float, height: float, spacing: float, radius: float, scale: float, **extra):
    """A woven generator table for a width x height (cm) piece at ``spacing / scale`` between threads."""
    sp = spacing / scale
    g = {"kind": "woven", "pattern": pattern, "ends": max(2, round(width / sp)), "picks": max(2, round(height / sp)),
         "spacing": round(sp, 6), "yarn_radius": round(radius / scale, 6), "crimp": WOVEN_CRIMP,
         "samples_per_cell": 4}
    g.update(extra)
    return g


def _knit(pattern: str, width: float, height: float, spacing: float, scale: float):
    sp = spacing / scale
    return {"kind": "knit", "pattern": pattern, "ends": max(2, round(width / sp)),
            "picks": max(2, round(height / (0.8 * sp))), "spacing": round(sp, 6), "course_spacing": round(0.8 * sp, 6),
            "samples_per_cell": 12}


def _yt(preset: str, color, bcsdf: str, radius: float | None = None) -> dict:
    t = {"preset": preset, "color": [round(c, 3) for c in color], "bcsdf": bcsdf}
    if radius is not None:
        t["radius"] = radius
    return t


def _count(gen: dict) -> int:
    return gen["ends"] + gen["picks"] if gen["kind"] == "woven" else gen["picks"]


def write_room(out_dir, scale: float = 1.0) -> RoomFiles:
    """Write the room's scene (``room.toml``), meshes, pile and draft into ``out_dir`` (module doc); the scene
    file last, so a failure leaves no scene naming files that are not there."""
    if not (isinstance(scale, (int, float)) and 0.01 <= scale <= 4.0 and math.isfinite(scale)):
        raise LoomError(None, "--scale", f"scale must be in [0.01, 4], got {scale}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise LoomError(out, None, "is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    meshes, cloth_width = _write_meshes(out)
    pile = pile_tufts(196.0, 216.0, 1.05 / math.sqrt(scale), (1.8, 2.6), TUFT_LOOP / math.sqrt(scale))
    from .io import bcc

    bcc.write(out / "rug_pile.bcc", pile, text="loomlight room: loop pile")
    # the wall hanging's draft travels with the scene (a copy of the bundled one)
    (out / "2229.wif").write_bytes(HANGING_DRAFT.read_bytes())
    fabrics, yarns = _textiles(scale, cloth_width, len(pile.points))
    scene = out / "room.toml"
    tmp = out / ".room.toml.tmp"
    tmp.write_text(_scene_text(scale, fabrics, yarns))
    tmp.replace(scene)
    return RoomFiles(scene, tuple(meshes), out / "rug_pile.bcc", yarns)


def _write_meshes(out: Path) -> tuple[list[Path], float]:
    """The room's OBJ meshes written into ``out``, and the tablecloth's width along its profile."""
    W, D, H = ROOM_SIZE
    meshes = []

    # --- the shell: floor, ceiling, side walls, the back wall around its two windows
    shell = _Obj("The room's shell (loomlight room): floor, ceiling, side walls and the back wall around two "
                 "windows; centimetres, z up")
    shell.box((-WALL, FRONT, -WALL), (W + WALL, D + WALL, 0.0))
    shell.box((-WALL, FRONT, H), (W + WALL, D + WALL, H + WALL))
    shell.box((-WALL, FRONT, 0), (0.0, D, H))
    shell.box((W, FRONT, 0), (W + WALL, D, H))
    xs = [0.0] + [x for w in WINDOWS for x in w] + [W]
    for i in range(0, len(xs), 2):       # full-height pieces between the windows
        shell.box((xs[i], D, 0), (xs[i + 1], D + WALL, H))
    for x0, x1 in WINDOWS:               # under the sill, over the lintel
        shell.box((x0, D, 0), (x1, D + WALL, WINDOW_Z[0]))
        shell.box((x0, D, WINDOW_Z[1]), (x1, D + WALL, H))
    meshes.append(shell.write(out / "shell.obj"))
    panes = _Obj("Two window panes behind the back wall's openings: the daylight (an area light)")
    for x0, x1 in WINDOWS:
        panes.box((x0, D + WALL + 2, WINDOW_Z[0]), (x1, D + WALL + 3, WINDOW_Z[1]))
    meshes.append(panes.write(out / "panes.obj"))
    lamp = _Obj("A ceiling lamp: a flat emitting box under the ceiling")
    lamp.box((215, 170, H - 4), (285, 230, H - 1))
    meshes.append(lamp.write(out / "lamp.obj"))

    # --- furniture: sofa along the left wall, table in the middle, a low shelf, the rug's backing
    sofa = _Obj("A sofa along the left wall: seat, back, two arms (boxes)")
    sofa.box((15, 110, 0), (105, 300, 42))
    sofa.box((0, 110, 0), (20, 300, 85))
    sofa.box((0, 90, 0), (105, 110, 58))
    sofa.box((0, 300, 0), (105, 320, 58))
    meshes.append(sofa.write(out / "sofa.obj"))
    table = _Obj("A table: a 120 x 80 top 72 cm high on four legs")
    table.box((190, 160, 68), (310, 240, 72))
    for x in (195, 299):
        for y in (165, 229):
            table.box((x, y, 0), (x + 6, y + 6, 68))
    meshes.append(table.write(out / "table.obj"))
    shelf = _Obj("A low shelf against the right wall")
    shelf.box((455, 180, 0), (498, 330, 75))
    meshes.append(shelf.write(out / "shelf.obj"))
    backing = _Obj("The rug's backing: a thin box under its pile")
    backing.box((150, 80, 0), (350, 300, 0.6))
    meshes.append(backing.write(out / "backing.obj"))
    vase = _Obj("A glass vase on the shelf: a closed box, wound outward")
    vase.box((466, 240, 75), (486, 260, 105))
    meshes.append(vase.write(out / "vase.obj"))
    P, UV = cushion_grid(44.0, 9.0)
    meshes.append(_Obj("A cushion's face (z = 9 (1 - x^4)(1 - y^4) over 44 x 44 cm) with uv: the cushions' "
                       "drape surface").grid(P, UV).write(out / "cushion.obj"))
    P, UV, cloth_w = tablecloth_grid(120.0, 80.0, 28.0, TABLECLOTH_BEND)
    meshes.append(_Obj("The tablecloth's surface: over the table's top (x across, 120 cm) with 28 cm drops, "
                       "uv = arc length").grid(P, UV).write(out / "tablecloth.obj"))
    roll = _Obj("The sofa arm's roll: a half cylinder of radius 9 along x, uv unused")
    a = np.linspace(0, math.pi, 13)
    R = np.stack([np.broadcast_to(np.array([0.0, 105.0])[:, None], (2, 13)),
                  np.broadcast_to(9 * np.cos(a)[None, :], (2, 13)),
                  np.broadcast_to(9 * np.sin(a)[None, :], (2, 13))], axis=-1)
    meshes.append(roll.grid(R).write(out / "roll.obj"))
    return meshes, cloth_w


def _textiles(scale: float, cloth_w: float, tufts: int) -> tuple[list[tuple[str, dict]], dict]:
    """The eleven ``[[fabrics]]`` tables, each with its comment, and the yarns of each (module doc)."""
    D = ROOM_SIZE[1]
    fabrics = []
    yarns = {}

    def add(name, comment, gen, types, transform=None, drape=None, source=None):
        f = {"name": name}
        if drape:
            f["drape"] = drape
        if transform:
            f["transform"] = transform
        f["fabric"] = source if source else {"source": "generator", "generator": gen}
        f["yarns"] = types
        fabrics.append((comment, f))

    upright = {"axis": [1.0, 0.0, 0.0], "degrees": 90.0}
    curtain = [("twill", "polyester1", (0.62, 0.12, 0.10), "polyester", "silk1", (0.80, 0.55, 0.25), "silk"),
               ("satin", "rayon1", (0.80, 0.76, 0.62), "silk", "rayon2", (0.76, 0.72, 0.60), "silk")]
    k = 0
    for w, (x0, x1) in enumerate(WINDOWS):
        for side in (0, 1):
            pattern, pw, cw, bw, pf, cf, bf = curtain[w]
            cx = x0 - 18 + side * (x1 - x0 + 36)
            gen = _woven(pattern, 46.0, 215.0, 0.32, 0.09, scale, pleats={"count": 5, "depth": PLEAT_DEPTH})
            add(f"curtain{k + 1}", f"a curtain at window {w + 1}, {'left' if not side else 'right'}: {pattern}, "
                "pleated and stood upright", gen,
                {"warp": _yt(pw, cw, bw), "weft": _yt(pf, cf, bf)},
                transform={"rotate": upright, "translate": [cx, D - 12.0, 5.0 + 107.5]})
            yarns[f"curtain{k + 1}"] = _count(gen)
            k += 1
    gen = _woven("plain", cloth_w, 80.0, 0.4, 0.11, scale)
    add("tablecloth", "a linen tablecloth over the table (an OBJ drape: top and two drops)", gen,
        {"warp": _yt("cotton1", (0.86, 0.84, 0.77), "cotton"), "weft": _yt("cotton2", (0.82, 0.80, 0.72), "cotton")},
        drape={"surface": "obj", "file": "tablecloth.obj"}, transform={"translate": [250.0, 200.0, 72.0]})
    yarns["tablecloth"] = _count(gen)
    for i, (pattern, preset, color, y) in enumerate(CUSHIONS):
        gen = _knit(pattern, 44.0, 44.0, 0.9, scale)
        add(f"cushion{i + 1}", f"a {pattern} cushion cover leaning on the sofa's back (an OBJ drape)", gen,
            {"knit": _yt(preset, color, "fleece")}, drape={"surface": "obj", "file": "cushion.obj"},
            transform=_cushion_place(y))
        yarns[f"cushion{i + 1}"] = _count(gen)
    gen = _knit("rib1x1", 28.0, 60.0, 0.8, scale)
    add("throw", "a throw over the sofa arm's roll (a cylinder drape)", gen,
        {"knit": _yt("cotton1", (0.55, 0.62, 0.48), "fleece")},
        drape={"surface": "cylinder", "radius": 9.0},
        transform={"rotate": {"axis": [0.0, 0.0, 1.0], "degrees": 90.0}, "translate": [52.0, 310.0, 58.0]})
    yarns["throw"] = _count(gen)
    pile_r = round(PILE_RADIUS / math.sqrt(scale), 6)
    add("rug", "the loop-pile rug: one U-shaped yarn per tuft (rug_pile.bcc), on its backing", None,
        {"other": _yt("polyester1", (0.55, 0.42, 0.30), "polyester", radius=pile_r)},
        source={"source": "file", "path": "rug_pile.bcc", "radius": pile_r},
        transform={"translate": [250.0, 190.0, 0.6]})
    yarns["rug"] = tufts
    reps = max(1, round(8 * scale))
    add("hanging", "a wall hanging between the windows: the WIF draft 2229, tiled", None,
        {"warp": _yt("silk1", (0.75, 0.68, 0.55), "silk"), "weft": _yt("rayon3", (0.30, 0.20, 0.45), "gabardine")},
        source={"source": "wif", "path": "2229.wif", "scale": round(18.0 / scale, 4), "crimp": HANGING_CRIMP,
                "repeat": [reps, round(1.3 * reps)]},
        transform={"rotate": upright, "translate": [250.0, D - 3.0, 150.0]})
    yarns["hanging"] = HANGING_THREADS * (reps + round(1.3 * reps))
    return fabrics, yarns


def _cushion_place(y: float) -> dict:
    """A cushion's placement (its fabric's and its core mesh's): face turned to lean on the sofa's back."""
    return {"rotate": {"axis": [0.0, 1.0, 0.0], "degrees": CUSHION_LEAN_DEG}, "translate": [32.0, y, 63.0]}


def _scene_text(scale: float, fabrics: list[tuple[str, dict]], yarns: dict) -> str:
    """room.toml: scene, fabrics, meshes, camera, lights and render settings."""
    lines = ["# loomlight room: a living room dressed in eleven procedural textiles, Sponza-class (Luan, Zhao, Bala",
             "# 2017 Fig. 1), written by `loomlight room` (pipeline/room.py) with its meshes and the rug's pile.",
             f"# scale = {scale}: {sum(yarns.values()):,} yarns. Centimetres, z up; the camera looks in from the "
             "room's open front.", "#", "#   loomlight render room.toml --method bysdf -o room.exr", ""]
    _table(lines, "scene", {"name": "room", "description": "a living room dressed in eleven procedural textiles",
                            "seed": 3})
    for comment, f in fabrics:
        lines += ["", f"# {comment}"]
        _table(lines, "[[fabrics]]", f)
    mats = [("shell", "shell.obj", {"type": "lambert", "albedo": [0.72, 0.70, 0.66]}),
            ("panes", "panes.obj", {"type": "lambert", "albedo": 0.0, "emission": [6.0, 6.4, 7.0]}),
            ("lamp", "lamp.obj", {"type": "lambert", "albedo": 0.0, "emission": [14.0, 12.5, 10.0]}),
            ("sofa", "sofa.obj", {"type": "lambert", "albedo": [0.35, 0.30, 0.26]}),
            ("table", "table.obj", {"type": "lambert", "albedo": [0.40, 0.25, 0.14]}),
            ("shelf", "shelf.obj", {"type": "lambert", "albedo": [0.55, 0.50, 0.42]}),
            ("backing", "backing.obj", {"type": "lambert", "albedo": [0.30, 0.24, 0.18]}),
            ("vase", "vase.obj", {"type": "dielectric", "eta": 1.5, "roughness": 0.05}),
            ("roll", "roll.obj", {"type": "lambert", "albedo": [0.35, 0.30, 0.26]}, {"translate": [0.0, 310.0, 58.0]})]
    for name, file, mat, *where in mats:
        lines.append("")
        _table(lines, "[[meshes]]", {"name": name, "file": file, "material": mat} | (
            {"transform": where[0]} if where else {}))
    for i, cushion in enumerate(CUSHIONS):
        lines.append("")
        _table(lines, "[[meshes]]", {"name": f"cushion{i + 1}-core", "file": "cushion.obj",
                                     "material": {"type": "lambert", "albedo": [0.5, 0.5, 0.5]},
                                     "transform": _cushion_place(cushion[-1])})
    lines.append("")
    _table(lines, "camera", {"origin": [250.0, -110.0, 185.0], "target": [250.0, 240.0, 45.0], "up": [0.0, 0.0, 1.0],
                             "fov": 70.0, "width": 640, "height": 360})
    lines.append("")
    _table(lines, "[[lights]]", {"type": "constant", "radiance": 0.2})
    lines.append("")
    _table(lines, "render", {"spp": 16, "seed": 3, "max_depth": 12})
    return "\n".join(lines) + "\n"
