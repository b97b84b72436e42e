"""Scenes of several fabrics (``[[fabrics]]``: pipeline/scene.py, pipeline/runners/ingest.py): read and checked,
ingested as one yarns artifact whose yarn types are (fabric, group) pairs, placed rigidly (curves and their frames
turn with the fabric), rendered by fiberpath, bysdf and volpath. References: a fabric placed outside the view
changes no pixel (fiberpath: the same bytes); a fabric moved by a rigid transform, seen by the camera and lit by
the light moved with it, is the same picture up to the transform's rounding (direct light) and within noise (with
bounces: the sky's and the pixels' samples are drawn in world axes); the placed curves are the rotated curves
exactly and their frames the rotated frames; bad fabrics exit 2 naming file and key."""
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.artifacts import Artifact
from pipeline.errors import LoomError
from pipeline.images import read_exr
from pipeline.scene import load_scene

FABRIC = """
[[fabrics]]
name = "{name}"
{transform}
[fabrics.fabric]
source = "generator"
[fabrics.fabric.generator]
kind = "{kind}"
pattern = "{pattern}"
ends = {ends}
picks = 4
spacing = {spacing}
{extra}
[fabrics.yarns.default]
bcsdf = "cotton"
color = {color}
"""
TAIL = """
[camera]
origin = {origin}
target = {target}
up = {up}
fov = 30.0
width = 24
height = 18
{lights}
[render]
spp = 8
max_depth = {depth}
"""
RED, BLUE = [0.85, 0.15, 0.1], [0.1, 0.2, 0.85]
ORIGIN, TARGET, UP = np.array([0.3, -0.6, 0.9]), np.zeros(3), np.array([0.0, 0.0, 1.0])
SUN_DIR = np.array([0.3, 0.2, -1.0])
# a rigid placement with every axis turned: 40 degrees about (1, 2, 3), then a translation
TURN = Rotation.from_rotvec(np.radians(40.0) * np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)).as_matrix()
SHIFT = np.array([1.5, -2.0, 0.7])


def _vec(v) -> str:
    return str([float(x) for x in v])


def fabric(name="a", color=RED, matrix=None, translate=None, knit=False) -> str:
    tf = {}
    if matrix is not None:
        tf["matrix"] = "[" + ", ".join(_vec(r) for r in matrix) + "]"
    if translate is not None:
        tf["translate"] = _vec(translate)
    transform = ("transform = { " + ", ".join(f"{k} = {v}" for k, v in tf.items()) + " }") if tf else ""
    kind = dict(kind="knit", pattern="stockinette", ends=3, spacing=0.25, extra="course_spacing = 0.2") if knit \
        else dict(kind="woven", pattern="plain", ends=4, spacing=0.1, extra="yarn_radius = 0.02")
    return FABRIC.format(name=name, transform=transform, color=_vec(color), **kind)


def sun(direction) -> str:
    return f'[[lights]]\ntype = "directional"\ndirection = {_vec(direction)}\nirradiance = 2.0\n'


SKY = '[[lights]]\ntype = "constant"\nradiance = 0.5\n'


def write_scene(path: Path, fabrics, lights, depth, origin=ORIGIN, target=TARGET, up=UP) -> Path:
    path.write_text("".join(fabrics) + TAIL.format(origin=_vec(origin), target=_vec(target), up=_vec(up),
                                                     lights=lights, depth=depth))
    return path


def realized(cli, scene: Path) -> Path:
    yarns, fibers = scene.with_suffix(".yarns.zarr"), scene.with_suffix(".fibers.zarr")
    assert cli("ingest", scene, "-o", yarns)[0] == 0
    code, _, err = cli("realize", yarns, "-o", fibers)
    assert code == 0, err
    return fibers


def fiberpath(cli, scene: Path, fibers: Path, name: str) -> np.ndarray:
    out = scene.parent / f"{name}.exr"
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fibers, "-o", out)
    assert code == 0, err
    return read_exr(out)[0]


# ------------------------------------------------------------------------------------------------ reading
def test_fabrics_read_as_parts_with_labelled_yarn_types(tmp_path):
    s = load_scene(write_scene(tmp_path / "s.toml", [fabric("cloth"), fabric("rug", BLUE, TURN, SHIFT, knit=True)],
                               SKY, 4))
    assert [p.name for p in s.parts] == ["cloth", "rug"] and s.several
    assert s.type_labels() == ["cloth.warp", "cloth.weft", "cloth.knit", "cloth.other",
                               "rug.warp", "rug.weft", "rug.knit", "rug.other"]
    assert s.yarn_type("rug.knit")["color"] == BLUE and s.yarn_type("cloth.warp")["color"] == RED
    assert s.type_place("rug.knit") == "fabrics[1].yarns.knit"
    assert s.parts[0].matrix is None
    assert np.allclose(s.parts[1].matrix[:, :3], TURN, atol=1e-12) and np.allclose(s.parts[1].matrix[:, 3], SHIFT)
    one = load_scene(write_scene(tmp_path / "one.toml", [fabric("cloth")], SKY, 4))
    assert not one.several and one.type_labels() == ["warp", "weft", "knit", "other"]
    assert one.type_place("warp") == "fabrics[0].yarns.warp"


def test_ingest_gives_each_fabric_its_yarn_types_and_places_it_rigidly(cli, tmp_path):
    """Two fabrics: type = fabric * 4 + group, colours per fabric; the placed knit's control points are the knit's
    alone moved by the placement, and its frames the alone frames turned (the frames start from the turned up)."""
    both = write_scene(tmp_path / "both.toml", [fabric("cloth"), fabric("rug", BLUE, TURN, SHIFT, knit=True)], SKY, 4)
    alone = write_scene(tmp_path / "alone.toml", [fabric("rug", BLUE, knit=True)], SKY, 4)
    for s in (both, alone):
        assert cli("ingest", s, "-o", s.with_suffix(".zarr"))[0] == 0
    a, b = Artifact(both.with_suffix(".zarr")), Artifact(alone.with_suffix(".zarr"))
    woven = 8   # the 4 x 4 plain weave's ends and picks come first
    assert a["yarn_type"].tolist() == [0] * 4 + [1] * 4 + [6] * (len(a["yarn_type"]) - woven)
    assert a.summary["groups"] == ["cloth.warp", "cloth.weft", "rug.knit"]
    assert np.allclose(a["color"][:woven], RED) and np.allclose(a["color"][woven:], BLUE)
    off = int(a["curve_offsets"][woven])
    pa, pb = np.asarray(a["points"], float)[off:], np.asarray(b["points"], float)
    assert np.abs(pb @ TURN.T + SHIFT - pa).max() < 1e-6     # float32 storage of coordinates ~2
    fa = np.asarray(a["frame_normal"])[int(a["frame_offsets"][woven]):]
    # the frames are computed from the float32 control points, so they turn to float32 rounding, not exactly
    assert np.abs(np.asarray(b["frame_normal"]) @ TURN.T - fa).max() < 1e-5
    assert np.allclose(a["frame_twist"][woven:], b["frame_twist"], atol=1e-6)


# ------------------------------------------------------------------------------------------------ rendering
def test_a_fabric_outside_the_view_changes_no_pixel(cli, tmp_path):
    """Direct light from a directional light (max_depth 1): no ray of the picture can reach a fabric 30 units
    off to the side, so adding it leaves every byte of the picture as it was."""
    alone = write_scene(tmp_path / "alone.toml", [fabric("a")], sun(SUN_DIR), 1)
    both = write_scene(tmp_path / "both.toml", [fabric("a"), fabric("b", BLUE, translate=(30.0, 0.0, 0.0))],
                       sun(SUN_DIR), 1)
    x = fiberpath(cli, alone, realized(cli, alone), "alone")
    y = fiberpath(cli, both, realized(cli, both), "both")
    assert x.max() > 0.0 and np.array_equal(x, y)


def test_a_placed_fabric_is_the_same_fabric_seen_by_a_placed_camera(cli, tmp_path):
    """The fabric turned and moved, with the camera and the light moved by the same placement: direct light is
    the same picture up to the placement's rounding (every pixel but a grazing few within 1e-4 of the image's
    maximum, the means within 0.2 %); with a sky and bounces (max_depth 4) the image means agree within 1 %
    (the sky's and the pixels' samples are drawn in world axes, so the noise differs, not the expectation)."""
    def pair(lights, depth, tag):
        ref = write_scene(tmp_path / f"ref{tag}.toml", [fabric("a")], lights(SUN_DIR), depth)
        moved = write_scene(tmp_path / f"moved{tag}.toml", [fabric("a", RED, TURN, SHIFT)], lights(TURN @ SUN_DIR),
                            depth, origin=TURN @ ORIGIN + SHIFT, target=TURN @ TARGET + SHIFT, up=TURN @ UP)
        return ref, moved

    ref, moved = pair(sun, 1, 1)
    fr, fm = realized(cli, ref), realized(cli, moved)
    x, y = fiberpath(cli, ref, fr, "ref1"), fiberpath(cli, moved, fm, "moved1")
    close = np.all(np.abs(x - y) <= 1e-4 * x.max(), axis=-1)
    assert close.mean() >= 0.98, f"{(~close).sum()} pixels differ"
    assert abs(y.mean() / x.mean() - 1.0) < 2e-3
    ref, moved = pair(lambda d: sun(d) + SKY, 4, 4)
    x, y = fiberpath(cli, ref, fr, "ref4"), fiberpath(cli, moved, fm, "moved4")
    assert abs(y.mean() / x.mean() - 1.0) < 0.01


def _two(tmp_path, name, fabrics):
    return write_scene(tmp_path / name, fabrics, sun(SUN_DIR) + SKY, 8, origin=(0.5, -1.0, 1.2), target=(0.4, 0.0, 0.0))


CLOTH, RUG = fabric("cloth"), fabric("rug", BLUE, translate=(0.5, 0.0, 0.0), knit=True)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["bysdf", "volpath"])
def test_bysdf_and_volpath_render_each_fabric_in_its_colour(cli, tmp_path, method):
    """bysdf (yarn curves) and procedural volpath render both fabrics, each yarn in its fabric's colour: the
    pixels the red cloth covers when rendered alone are redder than blue in the picture of both, the pixels only
    the blue knit covers bluer than red."""
    def render(scene):
        out = scene.with_suffix(".exr")
        code, _, err = cli("render", scene, "--method", method, "-o", out, "--width", "48", "--height", "36")
        assert code == 0, err
        return read_exr(out)

    (both, ch), (_, alone) = render(_two(tmp_path, "both.toml", [CLOTH, RUG])), render(
        _two(tmp_path, "alone.toml", [CLOTH]))
    cloth, rug = alone["A"] > 0.5, (ch["A"] > 0.5) & (alone["A"] == 0.0)
    assert cloth.sum() > 20 and rug.sum() > 20
    r, b = both[..., 0], both[..., 2]
    assert r[cloth].mean() > 1.5 * b[cloth].mean() and b[rug].mean() > 1.5 * r[rug].mean()


# ------------------------------------------------------------------------------------------------ bad input
BAD = {
    "both tables": ('[fabric]\nsource = "generator"\n[fabric.generator]\nkind = "woven"\npattern = "plain"\n',
                    "fabrics"),
    "top-level yarns": ('[yarns.warp]\ncolor = [0.5, 0.5, 0.5]\n', "yarns"),
    "a second name": (fabric("a"), "fabrics[1].name"),
    "scale": (fabric("b").replace('name = "b"\n', 'name = "b"\ntransform = { scale = 2.0 }\n'),
              "fabrics[1].transform.scale"),
    "a reflection": (fabric("b", matrix=np.diag([1.0, 1.0, -1.0])), "fabrics[1].transform.matrix"),
    "a missing file": ('[[fabrics]]\nname = "c"\n[fabrics.fabric]\nsource = "file"\npath = "none.bcc"\n',
                       "fabrics[1].fabric.path"),
    "an unknown pattern": (fabric("b").replace('pattern = "plain"', 'pattern = "plane"'),
                           "fabrics[1].fabric.generator.pattern"),
    "an infinite translation": (fabric("b").replace('name = "b"\n',
                                                    'name = "b"\ntransform = { translate = [inf, 0.0, 0.0] }\n'),
                                "fabrics[1].transform.translate[0]"),
    "a flat drape": (fabric("b").replace('name = "b"\n',
                                         'name = "b"\ndrape = { surface = "cylinder", radius = 0.0 }\n'),
                     "fabrics[1].drape.radius"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_fabrics_exit_2_naming_file_and_key(cli, tmp_path, case):
    extra, key = BAD[case]
    scene = tmp_path / "bad.toml"
    scene.write_text(fabric("a") + extra + TAIL.format(origin=_vec(ORIGIN), target=_vec(TARGET), up=_vec(UP),
                                                       lights=SKY, depth=4))
    with pytest.raises(LoomError) as e:
        load_scene(scene)
    assert e.value.place == key, e.value
    code, _, err = cli("ingest", scene, "-o", tmp_path / "y.zarr")
    assert code == 2 and f"bad.toml: {key}" in err and "Traceback" not in err
    assert not (tmp_path / "y.zarr").exists()


def test_methods_of_one_fabric_refuse_several(cli, tmp_path):
    """prt, btf and fiberpath_shell render a tiling's one fabric: a scene of several is refused before anything
    is read or built."""
    scene = _two(tmp_path, "both.toml", [CLOTH, RUG])
    for method in ("prt", "btf", "fiberpath_shell"):
        code, _, err = cli("render", scene, "--method", method, "-o", tmp_path / "x.exr")
        assert code == 2 and "both.toml: fabrics: " in err and "Traceback" not in err, err
        assert not (tmp_path / "x.exr").exists()


def test_a_tiling_refuses_a_scene_of_several_fabrics(cli, tmp_path):
    """A tiling takes its yarn types from one fabric's scene: a tile configuration naming a scene of several is
    refused (exit 2, the configuration and its key ``scene``), nothing written."""
    scene = _two(tmp_path, "both.toml", [CLOTH, RUG])
    cfg = tmp_path / "t.toml"
    cfg.write_text(f'scene = "{scene.name}"\n[weave]\nspacing = [0.1, 0.1]\n[[exemplars]]\npattern = "satin"\nn = 5\n'
                   '[tiling]\nrepeat = [1, 1]\n[surface]\nkind = "flat"\nresolution = [2, 2]\n')
    code, _, err = cli("tile", cfg, "-o", tmp_path / "tiling.zarr")
    assert code == 2 and "t.toml: scene: both.toml has several [[fabrics]]" in err and "Traceback" not in err, err
    assert not (tmp_path / "tiling.zarr").exists()


def test_a_bad_curve_of_a_second_fabric_is_named_in_its_own_file(cli, tmp_path):
    """A repeated control point in the second fabric's curve file, with that fabric's merge_duplicates = false:
    exit 2 naming the curve file and the curve's index there (not its index among all the scene's curves)."""
    (tmp_path / "strands.txt").write_text("0 0 0 0.02\n1 0 0 0.02\n\n0 1 0 0.02\n0.5 1 0 0.02\n0.5 1 0 0.02\n"
                                          "1 1 0 0.02\n")
    part = ('[[fabrics]]\nname = "strands"\n[fabrics.fabric]\nsource = "file"\npath = "strands.txt"\n'
            'merge_duplicates = false\n[fabrics.yarns.default]\nbcsdf = "cotton"\n')
    scene = write_scene(tmp_path / "s.toml", [fabric("a"), part], SKY, 4)
    code, _, err = cli("ingest", scene, "-o", tmp_path / "y.zarr")
    assert code == 2 and "strands.txt: curve 1, point 2: repeated consecutive control point" in err, err
    assert not (tmp_path / "y.zarr").exists()
    scene.write_text(scene.read_text().replace("merge_duplicates = false\n", ""))    # merged with a warning
    code, _, err = cli("ingest", scene, "-o", tmp_path / "y.zarr")
    assert code == 0 and "merged 1 repeated" in err, err


# ------------------------------------------------------------------------------------------------ drape
def _flat_and_draped(spec, knit=False):
    from pipeline.generators import generate
    from pipeline.runners.ingest import draped

    gen = {"kind": "knit", "pattern": "stockinette", "ends": 3, "picks": 4, "spacing": 0.25} if knit else \
        {"kind": "woven", "pattern": "plain", "ends": 6, "picks": 5, "spacing": 0.1, "yarn_radius": 0.02}
    flat = np.concatenate(generate(dict(gen)).points)
    lo, hi = flat.min(axis=0), flat.max(axis=0)
    centre = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.0])
    return flat - centre, np.concatenate(draped(generate(dict(gen)), spec, Path("s.toml"), "drape").points)


@pytest.mark.parametrize("knit", [False, True])
def test_a_cylinder_drape_keeps_lengths_and_thickness(knit):
    """Over a cylinder of radius R (axis y): every control point at distance R + z from the axis, at polar angle
    x / R from +z (the cloth's lengths kept along the surface), y unchanged -- to 1e-9 (the normal's central
    differences)."""
    R = 0.3
    q, p = _flat_and_draped({"surface": "cylinder", "radius": R}, knit)
    assert np.allclose(np.hypot(p[:, 0], p[:, 2]), R + q[:, 2], atol=1e-9)
    assert np.allclose(np.arctan2(p[:, 0], p[:, 2]), q[:, 0] / R, atol=1e-9) and np.allclose(p[:, 1], q[:, 1])


def test_a_sphere_drape_lays_the_middle_on_the_ball():
    """Over a ball of radius R: a control point whose cloth distance r from the centre is within the dome
    (r < pi R / 2) lies at distance R + z from the ball's centre, at polar angle r / R; beyond, the cloth hangs
    below the equator."""
    R = 0.15
    q, p = _flat_and_draped({"surface": "sphere", "radius": R, "folds": 6, "fold_amplitude": 0.15})
    r = np.hypot(q[:, 0], q[:, 1])
    dome = r < 0.5 * np.pi * R - 1e-3
    assert dome.sum() > 100 and (~dome).sum() > 50
    assert np.allclose(np.linalg.norm(p[dome], axis=1), R + q[dome, 2], atol=1e-9)
    assert np.allclose(np.arccos(p[dome, 2] / np.linalg.norm(p[dome], axis=1)), r[dome] / R, atol=1e-6)
    assert np.all(p[~dome, 2] < 0.05)


# ------------------------------------------------------------------------------------------------ drape on an OBJ
def _write_obj(path: Path, V, UV, F, uv=True) -> Path:
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in V]
    if uv:
        lines += [f"vt {float(u)!r} {float(v)!r}" for u, v in UV]
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in F]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    path.write_text("\n".join(lines) + "\n")
    return path


def _flat_and_on_obj(tmp_path, V, UV, F, **spec):
    from pipeline.generators import generate
    from pipeline.runners.ingest import draped

    gen = {"kind": "woven", "pattern": "plain", "ends": 6, "picks": 5, "spacing": 0.1, "yarn_radius": 0.02}
    flat = np.concatenate(generate(dict(gen)).points)
    obj = _write_obj(tmp_path / "surface.obj", V, UV, F)
    on = draped(generate(dict(gen)), {"surface": "obj", "file": str(obj), **spec}, Path("s.toml"), "drape")
    return flat - np.array([*flat.min(axis=0)[:2], 0.0]), np.concatenate(on.points)


def test_an_obj_drape_through_a_flat_chart_is_a_translation(tmp_path):
    """A flat rectangle of the fabric's own size with uv over [0, 1]^2, its triangles listed clockwise in uv half
    of them: the fabric lands on it moved to the rectangle's corner, every control point to 1e-12."""
    from pipeline.generators import generate
    from stages.tile.base_surfaces import flat_rectangle

    pts = np.concatenate(generate({"kind": "woven", "pattern": "plain", "ends": 6, "picks": 5, "spacing": 0.1,
                                   "yarn_radius": 0.02}).points)
    w, h = pts.max(axis=0)[:2] - pts.min(axis=0)[:2]
    V, UV, F = flat_rectangle(w, h, 5, 3)
    F[::2] = F[::2][:, [0, 2, 1]]
    q, p = _flat_and_on_obj(tmp_path, V, UV, F)
    assert np.allclose(p, q, atol=1e-12, rtol=0)


def test_an_obj_drape_follows_a_cylinder_to_its_chords(tmp_path):
    """An OBJ cylinder (radius R, 64 facets over 90 degrees, u along the angle) with uv_size making its uv map keep
    lengths: every control point at distance R + z from the axis within the facets' sag R (1 - cos(dphi / 2)), at
    the angle its arc length from the fabric's edge gives (within dphi^2), y kept to 1e-12."""
    from stages.tile.base_surfaces import cylinder

    R, L, A, nu = 0.5, 1.0, 90.0, 64
    V, UV, F = cylinder(R, L, A, nu, 4)
    a, dphi = np.radians(A), np.radians(A) / nu
    q, p = _flat_and_on_obj(tmp_path, V, UV, F, uv_size=[R * a, L])
    sag = R * (1.0 - np.cos(0.5 * dphi))
    assert np.all(np.abs(np.hypot(p[:, 0], p[:, 2]) - (R + q[:, 2])) <= sag + 1e-12)
    assert np.allclose(np.arctan2(p[:, 0], p[:, 2]), q[:, 0] / R - 0.5 * a, atol=dphi ** 2, rtol=0)
    assert np.allclose(p[:, 1], q[:, 1], atol=1e-12, rtol=0)


def test_the_bundled_cushion_takes_a_fabric_on_its_top():
    """The bundled cushion (a 32 x 32 height field with uv): a fabric's uv at height 0 lands on the surface --
    within the facets' linear-interpolation error of its analytic height f = 0.2 (1 - x^4)(1 - y^4),
    h^2 / 8 (|f_XX| + 2 |f_XY| + |f_YY|) = 5.5e-3 at h = 1/32 (measured 2.5e-3) --
    and at height z exactly z from there along a unit normal that points up."""
    from pipeline.io.obj_mesh import read_obj_mesh
    from stages.tile.base_surfaces import chart_points, uv_chart

    m = read_obj_mesh(Path(__file__).resolve().parents[2] / "data" / "meshes" / "cushion.obj", None)
    chart = uv_chart(m.V, m.UV, m.F)
    u, v = np.random.default_rng(3).random((2, 2000))
    z = np.full(2000, 0.03)
    base, out0 = chart_points(chart, u, v, np.zeros(2000))
    lifted, out1 = chart_points(chart, u, v, z)
    assert not out0.any() and not out1.any() and len(m.F) == 2 * 32 * 32
    x, y = 2.0 * u - 1.0, 2.0 * v - 1.0
    assert np.allclose(base[:, :2], np.c_[u - 0.5, v - 0.5], atol=1e-6)
    assert np.all(np.abs(base[:, 2] - 0.2 * (1.0 - x ** 4) * (1.0 - y ** 4)) <= (9.6 + 2.0 * 12.8 + 9.6) / 32 ** 2 / 8)
    step = lifted - base
    assert np.allclose(np.linalg.norm(step, axis=1), z) and np.all(step[:, 2] > 0.0)


OBJ_DRAPE = 'drape = {{ surface = "obj", file = "{file}"{more} }}\n'


@pytest.mark.parametrize("case", ["missing", "radius", "no uv", "outside"])
def test_a_bad_obj_drape_exits_2_naming_the_key(cli, tmp_path, case):
    """A missing OBJ (read), a radius on an OBJ drape (read), an OBJ without texture coordinates (ingest), a fabric
    beyond the mesh's uv chart (ingest): exit 2, one line naming the scene and the drape's key, nothing written."""
    from stages.tile.base_surfaces import flat_rectangle

    V, UV, F = flat_rectangle(1.0, 1.0, 2, 2)
    _write_obj(tmp_path / "plain.obj", V, UV, F, uv=case != "no uv")
    file, more, key = {"missing": ("none.obj", "", "fabrics[1].drape.file"),
                       "radius": ("plain.obj", ", radius = 1.0", "fabrics[1].drape.radius"),
                       "no uv": ("plain.obj", "", "fabrics[1].drape.file"),
                       "outside": ("plain.obj", ", uv_size = [0.1, 0.1]", "fabrics[1].drape")}[case]
    extra = fabric("b").replace('name = "b"\n', 'name = "b"\n' + OBJ_DRAPE.format(file=file, more=more))
    scene = tmp_path / "bad.toml"
    scene.write_text(fabric("a") + extra + TAIL.format(origin=_vec(ORIGIN), target=_vec(TARGET), up=_vec(UP),
                                                       lights=SKY, depth=4))
    code, _, err = cli("ingest", scene, "-o", tmp_path / "y.zarr")
    where = "plain.obj" if case == "no uv" else "bad.toml"
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"{where}: " in err and (key in err or case == "no uv"), err
    assert not (tmp_path / "y.zarr").exists()
