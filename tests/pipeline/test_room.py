"""The Sponza-class room (``loomlight room``, pipeline/room.py): a scene written by code that the scene reader
takes, whose yarn counts are the ingested ones, every fabric inside the room, its surfaces' uv keeping lengths,
and (slow) a full room that ``realize`` refuses with its 800+ GB and that bysdf renders."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.artifacts import Artifact
from pipeline.room import ROOM_SIZE, pile_tufts, tablecloth_grid, tablecloth_profile, write_room
from pipeline.scene import load_scene


def test_the_room_is_a_scene_of_eleven_textiles_of_every_kind(tmp_path):
    """The full room reads as a scene (every key, preset, BCSDF, OBJ and curve file checked by the reader): 11
    textiles -- pleated woven curtains, knits of three patterns, a WIF draft, a curve-file pile; OBJ and cylinder
    drapes -- of at least five yarn presets, with meshes that emit and one of glass, and over 30,000 yarns."""
    files = write_room(tmp_path)
    sc = load_scene(files.scene)
    assert len(sc.parts) == 11 and [p.name for p in sc.parts] == list(files.yarns)
    gens = [p.fabric.get("generator", {}) for p in sc.parts]
    assert sum("pleats" in g for g in gens) == 4
    assert {g["pattern"] for g in gens if g.get("kind") == "knit"} == {"stockinette", "garter", "rib1x1"}
    assert {g["pattern"] for g in gens if g.get("kind") == "woven"} >= {"twill", "satin", "plain"}
    assert {p.fabric["source"] for p in sc.parts} == {"generator", "wif", "file"}
    assert {(p.drape or {}).get("surface") for p in sc.parts} == {None, "obj", "cylinder"}
    presets = {t["preset"] for p in sc.parts for t in p.yarns.values()}
    assert len(presets) >= 5
    assert any(max(m["emission"]) > 0 for m in sc.meshes) and any(m["type"] == "dielectric" for m in sc.meshes)
    assert files.total_yarns >= 30_000 and files.yarns["rug"] > 25_000


def test_the_counts_are_the_ingested_yarns_and_every_fabric_is_inside_the_room(cli, tmp_path):
    """A tenth of the room (scale 0.1): ingest makes exactly the yarns write_room counts, fabric by fabric (type =
    fabric * 4 + group), and every control point lies inside the room, above the floor and below the ceiling."""
    files = write_room(tmp_path, scale=0.1)
    code, _, err = cli("ingest", files.scene, "-o", tmp_path / "yarns.zarr")
    assert code == 0, err
    a = Artifact(tmp_path / "yarns.zarr")
    per_fabric = np.bincount(np.asarray(a["yarn_type"]) // 4, minlength=len(files.yarns))
    assert per_fabric.tolist() == list(files.yarns.values())
    P = np.asarray(a["points"], float)
    W, D, H = ROOM_SIZE
    assert P.min(0).tolist() > [0.0, 0.0, 0.0] and P.max(0).tolist() < [W, D, H]


def test_the_tablecloth_surface_keeps_lengths():
    """The tablecloth's uv is arc length: along the profile, |dP/du| is the profile's total length on every
    segment (to float rounding), along y |dP/dv| the depth; the profile's length is its drops, top and bends'
    chords, and it ends hanging straight down at the drop."""
    top, depth, drop, bend = 120.0, 80.0, 28.0, 1.5
    P, UV, total = tablecloth_grid(top, depth, drop, bend)
    assert total == tablecloth_profile(top, drop, bend)[1][-1]
    n = 6       # chords per bend
    P2, s = tablecloth_profile(top, drop, bend, n_bend=n)
    chords = 2 * n * 2 * bend * math.sin(math.pi / (4 * n))
    assert s[-1] == pytest.approx(2 * (drop - bend) + top + chords, rel=1e-12)
    du = np.linalg.norm(np.diff(P, axis=1), axis=-1) / np.diff(UV[..., 0], axis=1)
    dv = np.linalg.norm(np.diff(P, axis=0), axis=-1) / np.diff(UV[..., 1], axis=0)
    assert np.allclose(du, total, rtol=1e-9) and np.allclose(dv, depth, rtol=1e-12)
    assert P2[0].tolist() == [-0.5 * top - bend, -drop] and P2[-1].tolist() == [0.5 * top + bend, -drop]
    assert np.allclose(P2[len(P2) // 2 - 1:len(P2) // 2 + 1, 1], 0.0)


def test_the_pile_is_one_grounded_tuft_per_grid_cell():
    """Tufts on a jittered grid: floor(w / p) x floor(d / p) of them, each starting and ending on the backing
    (z = 0) within the rug's grid (up to a cell's jitter and half a loop), rising to its legs' height plus the
    half circle's radius, and the layout fixed by its seed."""
    cs = pile_tufts(20.0, 12.0, 1.0, (1.4, 2.2), 0.5)
    assert len(cs.points) == 20 * 12
    ends = np.array([[p[0], p[-1]] for p in cs.points])
    assert np.all(ends[..., 2] == 0.0)
    reach = -0.2 * 1.0 + 0.5 * 0.5     # a cell's centre jitters 0.3 pitch from half a pitch in; the loop's half width
    assert np.abs(ends[..., 0]).max() <= 10.0 + reach and np.abs(ends[..., 1]).max() <= 6.0 + reach
    tops = np.array([p[:, 2].max() for p in cs.points])     # the legs' height and the half circle's radius
    assert tops.min() >= 1.4 + 0.25 - 1e-12 and tops.max() <= 2.2 + 0.25 + 1e-12
    again = pile_tufts(20.0, 12.0, 1.0, (1.4, 2.2), 0.5)
    assert all(np.array_equal(p, q) for p, q in zip(cs.points, again.points))


def test_the_room_command_writes_the_scene_and_refuses_a_bad_scale(cli, tmp_path):
    """``loomlight room -o DIR`` says what it wrote; a scale out of range or an output that is a file exits 2 with
    one line naming the option or the path, and writes no scene."""
    code, out, err = cli("room", "-o", tmp_path / "r", "--scale", "0.1")
    assert code == 0, err
    assert "11 textiles" in out and (tmp_path / "r" / "room.toml").is_file()
    code, _, err = cli("room", "-o", tmp_path / "s", "--scale", "0")
    assert code == 2 and "--scale" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "s").exists()
    (tmp_path / "f").write_text("x")
    code, _, err = cli("room", "-o", tmp_path / "f")
    assert code == 2 and str(tmp_path / "f") in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_realize_refuses_the_full_room_with_its_size(cli, tmp_path):
    """The full room holds over 800 GB of fibres if realized (Luan, Zhao, Bala 2017's Sponza: 867 GB):
    ``realize`` refuses it from its estimate, naming the size, exit 2, nothing written."""
    files = write_room(tmp_path)
    assert cli("ingest", files.scene, "-o", tmp_path / "yarns.zarr")[0] == 0
    code, _, err = cli("realize", tmp_path / "yarns.zarr", "-o", tmp_path / "fibers.zarr")
    assert code == 2 and "realized fibres" in err
    gib = float(err.split("realized fibres ")[1].split(" GiB")[0])
    assert gib * 2 ** 30 > 800e9
    assert not (tmp_path / "fibers.zarr").exists()


@pytest.mark.slow
def test_bysdf_renders_a_tenth_of_the_room(cli, tmp_path):
    """bysdf renders the room (scale 0.1) from its camera: finite, lit, the emitters seen at their radiance (the
    brightest pixels reach the window panes' emission), and the room closed around the camera: alpha (the share
    of a pixel's samples that meet anything) above 0.5 on at least 99 % of the pixels."""
    from pipeline.images import read_exr

    files = write_room(tmp_path, scale=0.1)
    out = tmp_path / "room.exr"
    code, _, err = cli("render", files.scene, "--method", "bysdf", "--width", "64", "--height", "36", "--spp", "4",
                       "-o", out)
    assert code == 0, err
    img, ch = read_exr(out)
    assert np.isfinite(img).all() and img.mean() > 0.02
    assert img.max() >= 6.0 - 1e-6
    assert (ch["A"] > 0.5).mean() >= 0.99, (ch["A"] > 0.5).mean()
