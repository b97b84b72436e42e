"""Scene files (pipeline/scene.py, schemas/scene.schema.json): the bundled scenes load; an unknown or
mistyped key, a bad value or broken TOML is a one-line error naming the file and the key; Mitsuba-style
camera conventions (row 0 at the top, full horizontal fov, right = forward x up) hold."""
import math

import numpy as np
import pytest

from pipeline.errors import LoomError
from pipeline.scene import camera_array, load_scene
from stages.render.camera import camera_ray, project_to_pixel
from tests.helpers import ROOT

DATA = ROOT / "data" / "scenes"

BASE = """
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
[camera]
origin = [0, -3, 1]
target = [0, 0, 0]
"""


def _scene(tmp_path, text):
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("path", sorted(DATA.glob("*.toml")), ids=lambda p: p.name)
def test_bundled_scenes_load(path):
    s = load_scene(path)
    assert s.fabric["source"] in ("file", "wif", "generator")


@pytest.mark.parametrize("extra, place", [
    ("[camera2]\nfov = 3\n", "camera2"),
    ("[render]\nssp = 4\n", "render.ssp"),
    ("[[lights]]\ntype = 'directional'\ndirection = [0, 0, -1]\nirradiance = 1\nirradience = 2\n",
     "lights[0].irradience"),
    ("[yarns.warp]\npreset = 'cotton1'\nradus = 0.1\n", "yarns.warp.radus"),
])
def test_unknown_key_is_named(tmp_path, extra, place):
    with pytest.raises(LoomError) as e:
        load_scene(_scene(tmp_path, BASE + extra))
    msg = e.value.one_line()
    assert place in msg and "unknown key" in msg and "s.toml" in msg and "\n" not in msg


@pytest.mark.parametrize("extra, word", [
    ("[render]\nspp = 0\n", "render.spp"),
    ("[[lights]]\ntype = 'sg'\naxis = [0, 0, 1]\nsharpness = -1\npower = 1\n", "lights[0].sharpness"),
    ("[[lights]]\ntype = 'laser'\n", "lights[0].type"),
    ("[[lights]]\ntype = 'directional'\ndirection = [0, 0, 0]\nirradiance = 1\n", "lights[0].direction"),
])
def test_bad_values_are_named(tmp_path, extra, word):
    with pytest.raises(LoomError) as e:
        load_scene(_scene(tmp_path, BASE + extra))
    assert word in e.value.one_line()


def test_broken_toml_names_line(tmp_path):
    with pytest.raises(LoomError) as e:
        load_scene(_scene(tmp_path, BASE + "\n[render\nspp = 3\n"))
    assert "line" in e.value.one_line()


def test_camera_conventions():
    cam = camera_array({"origin": [0, -5, 0], "target": [0, 0, 0], "up": [0, 0, 1], "fov": 90.0}, 200, 100)
    o, d = camera_ray(cam, 0, 199, 0.999999, 0.0)  # top-right corner
    # right edge at 45 degrees (full horizontal fov 90), image right = +x, row 0 is the top (+z)
    assert d[0] > 0 and d[2] > 0
    assert abs(math.degrees(math.atan2(d[0], d[1])) - 45.0) < 1e-3
    o, d = camera_ray(cam, 50, 100, 0.0, 0.0)  # image centre
    assert np.allclose(d, [0, 1, 0], atol=1e-12)
    col, row, z = project_to_pixel(cam, np.array([1.0, 0.0, 0.5]))
    o, d = camera_ray(cam, int(row), int(col), row - int(row), col - int(col))
    assert np.allclose(np.cross(d, np.array([1.0, 5.0, 0.5]) / np.linalg.norm([1.0, 5.0, 0.5])), 0, atol=1e-9)
