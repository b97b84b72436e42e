"""The prt studies (pipeline/runners/prt_study.py, ``loomlight study``).

References: cutting an IIRTF to a lower SH order equals precomputing it at that order with the same seed
(the precompute itself, on the tiny tiling: transfer matrices bit for bit, the BCSDF tables to rounding);
the error attribution against hand-computed sums (closed form); the term sweep wired through a stand-in
renderer whose single and multiple scattering parts are known, so every ratio is known exactly; bad study
files give one line naming the key and exit code 2.
"""
import json

import numpy as np
import pytest

from pipeline.errors import LoomError
from pipeline.images import write_render
from pipeline.runners import prt_study as ps
from pipeline.scene import load_scene

IIRTF_ARGS = ["--paths", "40", "--light-sampling", "mis", "--mfp-paths", "400", "--cell-factor", "3", "--chunk", "64",
              "--scene", "data/scenes/draped_damask.toml", "--exemplar", "0", "--layer-paths", "100",
              "--layer-bins", "2"]


@pytest.fixture(scope="module")
def tiny_iirtf(tmp_path_factory):
    """The precompute tests' tiny tiling with its exemplar 0's IIRTF at SH orders 1 and 2 (same seed)."""
    from pipeline.cli import main
    from tests.precompute.conftest import make_tiling

    d = tmp_path_factory.mktemp("prt_study")
    t = make_tiling(d)
    for L in (1, 2):
        assert main(["precompute", "iirtf", str(t), "-o", str(d / f"o{L}.zarr"), "--order", str(L), *IIRTF_ARGS]) == 0
    return t, d


def test_cut_equals_precompute_at_the_lower_order(tiny_iirtf):
    from pipeline.artifacts import Artifact

    t, d = tiny_iirtf
    ps.truncate_iirtf(d / "o2.zarr", 1, d / "cut1.zarr", t)
    direct, cut = Artifact(d / "o1.zarr", kind="iirtf"), Artifact(d / "cut1.zarr", kind="iirtf")
    assert set(direct.arrays()) == set(cut.arrays())
    for name in direct.arrays():
        a, b = direct[name], cut[name]
        assert a.shape == b.shape and a.dtype == b.dtype, name
        if name == "bcsdf_sh":
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
        else:
            assert np.array_equal(a, b), name
    assert cut.summary["order"] == 1 and cut.summary["sh_coefficients"] == 4 and cut.summary["cut_from_order"] == 2
    assert cut.summary["exemplars"][0]["bytes"] == direct.summary["exemplars"][0]["bytes"]
    # the cut records the tiling as its input: the prt renderer's same-tiling check reads this identity
    assert cut.meta["inputs"]["tiling"]["sha256"] == direct.meta["inputs"]["tiling"]["sha256"]
    with pytest.raises(LoomError, match="cannot cut an IIRTF of SH order 1 to order 2"):
        ps.truncate_iirtf(d / "o1.zarr", 2, d / "bad.zarr", t)
    assert not (d / "bad.zarr").exists()


def test_attribution_splits_the_error_into_its_terms():
    rng = np.random.default_rng(1)
    fp1 = rng.uniform(0.1, 1.0, (5, 3))
    rem = rng.uniform(0.1, 1.0, (5, 3))
    fp = fp1 + rem
    e_s = rng.normal(0, 0.05, (5, 3))
    e_m = rng.normal(0, 0.08, (5, 3))
    bg = rng.uniform(0.0, 0.3, (5, 3))            # light both prt term renders carry (misses, ground)
    prt = fp1 + e_s + rem + e_m
    ps_, pm = fp1 + e_s, rem + e_m + bg
    a = ps.attribute(fp, fp1, prt, ps_, pm)
    def r(x):
        return np.sqrt(np.mean(x ** 2))

    assert a["rmse"] == pytest.approx(r(e_s + e_m), rel=1e-12)
    assert a["rmse_single"] == pytest.approx(r(e_s), rel=1e-12)
    assert a["rmse_multi"] == pytest.approx(r(e_m), rel=1e-12)
    assert a["both_terms_mean"] == pytest.approx(bg.mean(), rel=1e-12)
    assert a["relative_rmse_multi"] == pytest.approx(r(e_m) / r(fp), rel=1e-12)
    assert a["multi_share_reference"] == pytest.approx(rem.sum() / fp.sum(), rel=1e-12)
    assert a["mean_error_single"] == pytest.approx(e_s.mean(), rel=1e-12)


def test_compare_gives_the_mean_intensity_ratios():
    ref = np.random.default_rng(2).uniform(0.1, 1.0, (12, 16, 3))
    test = ref * np.array([1.1, 0.9, 1.0])
    e = ps.compare(test, ref)
    np.testing.assert_allclose(e["ratio"], [1.1, 0.9, 1.0], rtol=1e-12)
    m = ref.reshape(-1, 3).mean(axis=0)
    d = m * np.array([0.1, -0.1, 0.0])
    assert e["mean_intensity_rel_error"] == pytest.approx(np.sqrt(np.mean(d ** 2)) / np.sqrt(np.mean(m ** 2)),
                                                          rel=1e-12)
    assert ps.compare(ref, ref)["ssim"] == pytest.approx(1.0)


# ------------------------------------------------------------------------------------------------ prt-terms
SCENE = """
[scene]
name = "terms-test"
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
width = 16
height = 12
[[lights]]
type = "constant"
radiance = 0.5
[render]
spp = 4
max_depth = 4
"""

SWEEP = """
[sweep]
name = "terms-unit"
scene = "scene.toml"
reference = "fiberpath"
render = { spp = 2, max_depth = 32 }

[[methods]]
name = "fiberpath"
args = ["--fibers", "nowhere.zarr"]

[[methods]]
name = "prt"
args = ["--fibers", "nowhere.zarr", "--set", "svf=s.zarr"]

[grid]
axes = [[0, 0, 1], [1, 0, 1]]
sharpness = [10]
power = 2.0
directional = true
irradiance = 1.5
"""

# the stand-in's parts: fiberpath single 1.0, multiple 0.5; prt single 0.9, multiple 0.6 (times the light);
# every render also carries BACKGROUND (pixels that miss the cloth and see the light), prt's term renders too
PARTS = {"fiberpath": (1.0, 0.5), "prt": (0.9, 0.6)}
BACKGROUND = 0.25


def _light_value(light):
    if light["type"] == "sg":
        return np.asarray(light["power"], float) * (0.5 + 0.5 * light["axis"][2])
    return np.asarray(light["irradiance"], float) * max(-light["direction"][2], 0.0)


def standin(calls):
    def render(scene_file, method, exr, args):
        sc = load_scene(scene_file)
        single, multi = PARTS[method]
        if method == "fiberpath":
            v = single if sc.render["max_depth"] == 1 else single + multi
        else:
            terms = [a.split("=", 1)[1] for a in args if a.startswith("terms=")]
            v = {"single": single, "multi": multi, "hits": 0.0 * single}[terms[-1]] if terms else single + multi
        v = v * _light_value(sc.lights[0]) + BACKGROUND
        write_render(exr, np.broadcast_to(v, (sc.camera["height"], sc.camera["width"], 3)).astype(np.float32))
        calls.append((exr.parent.name, exr.stem, sc.render["max_depth"], tuple(args)))
    return render


def _lights(out):
    """Configuration -> its light, from the derived scenes the term sweep rendered."""
    return {d.name: load_scene(d / "prt_single.scene.toml").lights[0] for d in (out / "renders").iterdir()}


def test_terms_attribute_a_sweep_to_single_and_multiple_scattering(tmp_path):
    from pipeline.runners.sweep import run_sweep

    (tmp_path / "scene.toml").write_text(SCENE)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(SWEEP)
    calls = []
    run_sweep(sweep, tmp_path / "full", renderer=standin(calls))
    assert len(calls) == 8
    calls.clear()
    res = ps.run_terms(sweep, tmp_path / "full", tmp_path / "terms", renderer=standin(calls))
    # the derived sweep: fiberpath at max_depth 1 with its own arguments, prt with terms=single / multi / hits
    seen = {(c[1], c[2], c[3]) for c in calls}
    assert ("fiberpath_single", 1, ("--fibers", "nowhere.zarr")) in seen
    assert ("prt_single", 32, ("--fibers", "nowhere.zarr", "--set", "svf=s.zarr", "--set", "terms=single")) in seen
    assert ("prt_multi", 32, ("--fibers", "nowhere.zarr", "--set", "svf=s.zarr", "--set", "terms=multi")) in seen
    assert ("prt_hits", 32, ("--fibers", "nowhere.zarr", "--set", "svf=s.zarr", "--set", "terms=hits")) in seen
    assert len(calls) == 16 and len(res.rows) == 4
    lv = {c: _light_value(sc_light) for c, sc_light in _lights(tmp_path / "terms").items()}
    for r in res.rows:
        v = lv[r["configuration"]]
        np.testing.assert_allclose(r["ratio"], 1.0, rtol=1e-6)
        np.testing.assert_allclose(r["single_ratio"], (0.9 * v + BACKGROUND) / (v + BACKGROUND), rtol=1e-6)
        np.testing.assert_allclose(r["multi_ratio"], 1.2, rtol=1e-5)     # the background cancels
        np.testing.assert_allclose(r["both_terms"], BACKGROUND, rtol=1e-5)
        np.testing.assert_allclose(r["multi_share"], np.sum(0.5 * v) / np.sum(1.5 * v + BACKGROUND), rtol=1e-6)
    s = res.summary
    V = np.array([lv[r["configuration"]] for r in res.rows])
    fp = 1.5 * V + BACKGROUND
    rms = np.sqrt(np.mean(fp ** 2))
    assert s["rmse"] == pytest.approx(0.0, abs=1e-6)
    assert s["relative_rmse_single"] == pytest.approx(np.sqrt(np.mean((0.1 * V) ** 2)) / rms, rel=1e-5)
    assert s["relative_rmse_multi"] == pytest.approx(np.sqrt(np.mean((0.1 * V) ** 2)) / rms, rel=1e-5)
    assert s["mean_error_single"] < 0 < s["mean_error_multi"]
    doc = json.loads((tmp_path / "terms" / "terms.json").read_text())
    assert doc["summary"]["configurations"] == 4
    assert "multi / remainder" in (tmp_path / "terms" / "attribution.md").read_text()
    t = s["time_per_image_s"]
    assert s["speedup_bound"] == pytest.approx(t["fiberpath"] / t["prt_hits"])
    calls.clear()
    ps.run_terms(sweep, tmp_path / "full", tmp_path / "terms", renderer=standin(calls))
    assert calls == []                                  # the term renders are reused while up to date


# ------------------------------------------------------------------------------------------------ bad input
GOOD = """
[study]
tiling = "{tiling}"
lights = [{{ type = "directional", direction = [0, 0, -1], irradiance = 1.0 }}]
iirtf = ["--paths", "10"]
[cell_size]
factors = [1.0, 2.0]
[sh_order]
orders = [0, 1]
"""


@pytest.mark.parametrize("edit, key", [
    (lambda s: s.replace("lights = [", "lightz = ["), "study.lights"),
    (lambda s: s + "[extra]\n", "extra"),
    (lambda s: s.replace('"--paths", "10"', '"--order", "3"'), "study.iirtf"),
    (lambda s: s.replace("factors = [1.0, 2.0]", "factors = [0.0]"), "cell_size.factors"),
    (lambda s: s.replace("orders = [0, 1]", "orders = [9]"), "sh_order.orders"),
    (lambda s: s.replace("[study]", "[study]\nreference = { spp = 0 }"), "study.reference.spp"),
    (lambda s: s.replace('tiling = "', 'tiling = "missing-'), "study.tiling"),
])
def test_bad_study_files_name_the_key(tmp_path, cli, edit, key):
    cfg = tmp_path / "tiling.toml"
    cfg.write_text("# stand-in\n")
    good = GOOD.format(tiling=cfg)
    (tmp_path / "good.toml").write_text(good)
    st = ps.load_study(tmp_path / "good.toml")
    assert st.max_order == 4 and st.iirtf_factors == [1.0, 2.0] and st.order_cell_factor == 1.0
    bad = tmp_path / "bad.toml"
    bad.write_text(edit(good))
    with pytest.raises(LoomError) as e:
        ps.load_study(bad)
    assert key in e.value.one_line()
    code, _, err = cli("study", "prt-params", bad, "-o", tmp_path / "out")
    assert code == 2 and key in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
