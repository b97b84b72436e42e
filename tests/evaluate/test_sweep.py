"""Sweeps (pipeline/runners/sweep.py, ``loomlight evaluate --sweep``) with a stand-in render method.

The stand-in, registered only inside these tests (monkeypatch), renders a checkerboard whose mean
is known in closed form from the derived scene (light kind, SG axis and sharpness, directional
direction) and scales it by 1.25 for ``render.source = "realized"``; it writes a render artifact
with a known wall time. References: the closed-form mean intensities give the RMSE of mean
intensity (seed 001 Fig. 13) exactly; the artifact times give the speed-up (seed 001 Table 2);
the scene overrides round-trip through the derived TOML scene.
"""
import hashlib
import json
import tomllib

import numpy as np
import pytest
import zarr

from pipeline.images import write_render
from pipeline.runners import sweep as sw
from pipeline.scene import load_scene

SCENE = """
[scene]
name = "sweep-test"
seed = 3
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 2
picks = 2
[camera]
origin = [0.0, -1.0, 1.0]
target = [0.0, 0.0, 0.0]
width = 20
height = 14
[[lights]]
type = "constant"
radiance = 0.5
[render]
spp = 4
source = "procedural"
"""

SWEEP = """
[sweep]
name = "unit"
scene = "scene.toml"
reference = "exact"
render = {{ spp = 2 }}
camera = {{ width = 16 }}

[[methods]]
name = "exact"
method = "standin"
render = {{ source = "procedural" }}

[[methods]]
name = "fast"
method = "standin"
render = {{ source = "{fast_source}" }}

[grid]
axes = [[0, 0, 1], [1, 0, 1]]
sharpness = [10, 100]
power = [1.0, 0.8, 0.6]
directional = true
irradiance = 2.0
views = [{{ name = "top", origin = [0, 0, 2], target = [0, 0, 0], up = [0, 1, 0] }}]

[[configurations]]
name = "grazing"
lights = [{{ type = "directional", direction = [-1.0, 0.0, -0.5], irradiance = 1.0 }}]
camera = {{ origin = [0, -2, 0.3] }}
"""

TIMES = {"procedural": 2.0, "realized": 0.5, "grid": 1.0}
SCALE = {"procedural": 1.0, "realized": 1.25, "grid": 0.9}


def standin_value(light) -> np.ndarray:
    """The stand-in's mean pixel value for a light (closed form)."""
    if light["type"] == "sg":
        return np.asarray(light["power"], float) * (0.5 + 0.5 * light["axis"][2]) * 10.0 / (10.0 + light["sharpness"])
    if light["type"] == "directional":
        return np.asarray(light["irradiance"], float) * max(-light["direction"][2], 0.0) * np.ones(3)
    return np.asarray(light["radiance"], float)


def _standin_method():
    """The stand-in as a registered render method (a scene's render.method is checked when it is read)."""
    from pipeline.renderers import RenderMethod, Source

    return RenderMethod("standin", "closed-form stand-in", "standin",
                        sources=tuple(Source(s, (), s) for s in SCALE), default_source="procedural")


def load_standin_scene(path):
    """``load_scene`` of a derived scene whose render.method is the stand-in."""
    from unittest import mock

    from pipeline.renderers import METHODS

    with mock.patch.dict(METHODS, {"standin": _standin_method()}):
        return load_scene(path)


def standin_render(calls):
    def render(scene_file, method, exr, args):
        assert method == "standin"
        sc = load_standin_scene(scene_file)
        v = standin_value(sc.lights[0]) * SCALE[sc.render["source"]]
        h, w = sc.camera["height"], sc.camera["width"]
        checker = 1.0 + 0.5 * np.where((np.add.outer(np.arange(h), np.arange(w)) % 2) == 0, 1.0, -1.0)
        write_render(exr, (checker[..., None] * v[None, None, :]).astype(np.float32))
        g = zarr.open_group(str(exr.with_suffix(".zarr")), mode="w", zarr_format=3)
        g.attrs["summary"] = {"kind": "render", "wall_time_s": TIMES[sc.render["source"]], "spp": sc.render["spp"]}
        g.attrs["loomlight"] = {"kind": "render", "complete": True, "wall_time_s": 99.0, "peak_memory_bytes": 1,
                                "content_hash": hashlib.sha256(exr.read_bytes()).hexdigest()}
        calls.append((exr.parent.name, exr.stem))
    return render


@pytest.fixture
def sweep_file(tmp_path):
    (tmp_path / "scene.toml").write_text(SCENE)
    p = tmp_path / "sweep.toml"
    p.write_text(SWEEP.format(fast_source="realized"))
    return p


def _expected_lights(sweep_path):
    raw = tomllib.loads(sweep_path.read_text())
    g = raw["grid"]
    out = {}
    for i, a in enumerate(g["axes"]):
        ax = (np.asarray(a, float) / np.linalg.norm(a)).tolist()
        for lam in g["sharpness"]:
            out[f"top_a{i}_l{lam:g}"] = {"type": "sg", "axis": ax, "sharpness": lam, "power": g["power"]}
        if g.get("directional"):
            out[f"top_a{i}_dir"] = {"type": "directional", "direction": (-np.asarray(ax)).tolist(),
                                    "irradiance": g["irradiance"]}
    d = np.array([-1.0, 0.0, -0.5])
    out["grazing"] = {"type": "directional", "direction": (d / np.linalg.norm(d)).tolist(), "irradiance": 1.0}
    return out


def test_sweep_closed_form_rmse_and_speedup(sweep_file, tmp_path):
    calls = []
    out = tmp_path / "out"
    res = sw.run_sweep(sweep_file, out, renderer=standin_render(calls))
    lights = _expected_lights(sweep_file)
    assert res.configurations == len(lights) == 7 and res.rendered == 14 and res.reused == 0
    ref = np.array([standin_value(l) for l in lights.values()])
    expected = np.sqrt(np.mean((0.25 * ref) ** 2))   # the fast method is 1.25x the reference
    assert res.methods["fast"]["rmse_mean_intensity"] == pytest.approx(expected, rel=1e-6)
    assert res.methods["exact"]["rmse_mean_intensity"] == 0.0
    assert res.methods["fast"]["relative_rmse_mean_intensity"] == pytest.approx(0.25, rel=1e-6)
    assert res.methods["fast"]["time_per_image_s"] == 0.5 and res.methods["fast"]["speedup"] == pytest.approx(4.0)
    assert res.methods["exact"]["speedup"] == pytest.approx(1.0)
    assert res.methods["fast"]["mean_ssim"] < 1.0
    doc = json.loads((out / "sweep.json").read_text())
    for c in doc["configurations"]:
        np.testing.assert_allclose(c["mean_intensity"]["exact"], standin_value(lights[c["name"]]), rtol=1e-6)
    m = json.loads((out / "metrics.json").read_text())
    assert set(m) == {f"{c}/fast.exr" for c in lights}
    # a uniform 1.25x scale of the checkerboard: RMSE = 0.25 x RMS of the reference pixels
    v = standin_value(lights["grazing"])
    assert m["grazing/fast.exr"]["rmse"] == pytest.approx(0.25 * np.sqrt(np.mean(v ** 2) * 1.25), rel=1e-5)
    for f in ("report.md", "report.html", "sweep_rmse.png", "sweep_scatter.png", "contact_sheet.png",
              "maps/grazing__fast.png"):
        assert (out / f).stat().st_size > 0, f
    md = (out / "report.md").read_text()
    assert "Fig. 13" in md and "Table 2" in md and "4.00x" in md
    from pipeline.artifacts import Artifact

    art = Artifact(out / "evaluation.zarr", kind="evaluation")
    assert art["mean_intensity"].shape == (7, 2, 3)
    assert art.summary["methods"]["fast"]["speedup"] == pytest.approx(4.0)


def test_derived_scenes_carry_overrides(sweep_file, tmp_path):
    out = tmp_path / "out"
    sw.run_sweep(sweep_file, out, renderer=standin_render([]))
    lights = _expected_lights(sweep_file)
    sc = load_standin_scene(out / "renders" / "top_a1_l100" / "fast.scene.toml")
    assert sc.lights[0]["type"] == "sg" and sc.lights[0]["sharpness"] == 100
    np.testing.assert_allclose(sc.lights[0]["axis"], lights["top_a1_l100"]["axis"], rtol=1e-12)
    assert len(sc.lights) == 1                       # the configuration replaces the scene's lights
    assert sc.render["spp"] == 2 and sc.render["source"] == "realized" and sc.render["method"] == "standin"
    assert sc.camera["width"] == 16 and sc.camera["height"] == 14 and sc.camera["origin"] == [0, 0, 2]
    g = load_standin_scene(out / "renders" / "grazing" / "exact.scene.toml")
    assert g.camera["origin"] == [0, -2, 0.3] and g.camera["target"] == [0.0, 0.0, 0.0]
    assert g.render["source"] == "procedural" and g.seed == 3


def _small(text):
    return text.replace("sharpness = [10, 100]", "sharpness = [10]").replace("directional = true",
                                                                             "directional = false")


def test_renders_reused_when_up_to_date(sweep_file, tmp_path, monkeypatch):
    sweep_file.write_text(_small(SWEEP.format(fast_source="realized")))   # 3 configurations x 2 methods
    out = tmp_path / "out"
    calls = []
    sw.run_sweep(sweep_file, out, renderer=standin_render(calls))
    assert len(calls) == 6
    calls.clear()
    res = sw.run_sweep(sweep_file, out, renderer=standin_render(calls))
    assert calls == [] and res.rendered == 0 and res.reused == 6
    (out / "renders" / "grazing" / "exact.exr").unlink()                # a missing image
    sweep_file.write_text(_small(SWEEP.format(fast_source="grid")))     # the fast method changed
    res = sw.run_sweep(sweep_file, out, renderer=standin_render(calls))
    assert sorted(calls) == sorted([(c, "fast") for c in _expected_lights(sweep_file)] + [("grazing", "exact")])
    assert res.methods["fast"]["speedup"] == pytest.approx(2.0)         # the grid stand-in takes 1 s
    calls.clear()
    sw.run_sweep(sweep_file, out, renderer=standin_render(calls), force=True)
    assert len(calls) == 6
    calls.clear()       # the code that decides the method's pictures changed: every render again
    monkeypatch.setattr(sw, "render_code_version", lambda method=None: "0123456789abcdef")
    res = sw.run_sweep(sweep_file, out, renderer=standin_render(calls))
    assert len(calls) == 6 and res.rendered == 6


def test_cli_sweep_with_registered_standin(cli, sweep_file, tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(sw, "known_methods", lambda: {"standin"})
    monkeypatch.setattr(sw, "cli_render", standin_render(calls))
    out = tmp_path / "cli"
    code, stdout, err = cli("evaluate", "--sweep", sweep_file, "-o", out)
    assert code == 0, err
    assert len(calls) == 14 and "speed-up 4.00x" in stdout and str(out / "report.md") in stdout


def test_sweep_bad_inputs_exit_2(cli, sweep_file, tmp_path):
    out = tmp_path / "bad"
    # the stand-in is not registered here: unknown method
    code, _, err = cli("evaluate", "--sweep", sweep_file, "-o", out)
    assert code == 2 and "standin" in err and "methods[0].method" in err
    cases = {
        "reference": SWEEP.format(fast_source="realized").replace('reference = "exact"', 'reference = "nope"'),
        "sharpness": SWEEP.format(fast_source="realized").replace("sharpness = [10, 100]", "sharpness = [0, 100]"),
        "unknown key": SWEEP.format(fast_source="realized").replace("[grid]", "[grid]\ncolour = 1"),
        "bad light": SWEEP.format(fast_source="realized").replace(
            'type = "directional", direction = [-1.0, 0.0, -0.5],', 'type = "directional", direction = [-1.0, 0.0],'),
    }
    for what, text in cases.items():
        sweep_file.write_text(text)
        code, _, err = cli("evaluate", "--sweep", sweep_file, "-o", out, "--no-render")
        assert code == 2, (what, err)
        assert "sweep.toml" in err and len(err.strip().splitlines()) == 1, (what, err)
    code, _, err = cli("evaluate", "--sweep", tmp_path / "missing.toml", "-o", out)
    assert code == 2 and "missing.toml" in err
    # nothing rendered yet and --no-render: a clear error, not an empty report
    sweep_file.write_text(SWEEP.format(fast_source="realized"))
    code, _, err = cli("evaluate", "--sweep", sweep_file, "-o", out, "--no-render")
    assert code == 2 and "reference" in err
    assert not (out / "report.md").exists()


def test_toml_writer_round_trip():
    doc = {"scene": {"name": "a \"q\" b", "seed": 3},
           "fabric": {"source": "generator", "generator": {"kind": "woven", "n": 2}},
           "lights": [{"type": "sg", "axis": [0.0, 0.6, 0.8], "sharpness": 1e-05, "power": [1, 2.5, 3]}],
           "render": {"ground": {"albedo": 0.5}, "flag": True}}
    assert tomllib.loads(sw.dumps_toml(doc)) == doc


def test_sweep_checks_its_base_scene_names_when_read(cli, sweep_file, tmp_path):
    """A misspelt name in the base scene is refused when the sweep is read, naming the scene file and
    key, before any configuration is rendered (pipeline.scene.load_scene's checks)."""
    (tmp_path / "scene.toml").write_text(SCENE + '[yarns.warp]\npreset = "coton1"\n')
    out = tmp_path / "bad_scene"
    code, _, err = cli("evaluate", "--sweep", sweep_file, "-o", out, "--no-render")
    assert code == 2, err
    assert "scene.toml: yarns.warp.preset: unknown preset 'coton1'" in err and "did you mean 'cotton1'" in err
    assert not out.exists() or not any(out.iterdir())


def test_render_key_follows_artifacts_named_in_set_options(tmp_path):
    """A render that reads an artifact through ``--set KEY=PATH`` (prt's svf= and iirtf=) is stale once that
    artifact changes: the artifact's content hash is part of the render's key (a plain path already was)."""
    art = tmp_path / "svf.bin"
    art.write_bytes(b"one")
    args = ["--set", f"svf={art}", "--set", "terms=single", str(art)]
    before = sw.arg_hashes(args)
    assert set(before) == {str(art)}
    art.write_bytes(b"two")
    assert sw.arg_hashes(args) != before
    assert sw.arg_hashes(["--set", "svf=no/such/file", "--set", "sg=mc"]) == {}
