"""`loomlight precompute svf|iirtf` end to end on the tiny tiling (issue 17 items 1, 5, 7, 8): the info
contract, skipping when up to date, identical array bytes at 1 and 2 threads (reference: the sha256 of
every array recorded at write), the inspector pictures, and every bad input -> exit code 2, one line,
nothing written and an existing artifact untouched."""
import json
from pathlib import Path

import numpy as np
import pytest

from pipeline.artifacts import read_meta

SVF_ARGS = ["--resolution", "16", "--components", "4", "--chunk", "200"]
IIRTF_ARGS = ["--order", "2", "--paths", "40", "--light-sampling", "mis", "--mfp-paths", "400", "--cell-factor", "3",
              "--chunk", "64", "--scene", "data/scenes/draped_damask.toml", "--layer-paths", "100", "--layer-bins", "2"]


def _arrays(path):
    return {k: v["sha256"] for k, v in read_meta(path)["arrays"].items()}


@pytest.fixture(scope="module")
def built(tiny_tiling, tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("precompute")
    tiling = tiny_tiling[0]
    assert main(["precompute", "svf", str(tiling), "-o", str(d / "svf.zarr"), *SVF_ARGS, "--threads", "2"]) == 0
    assert main(["precompute", "iirtf", str(tiling), "-o", str(d / "iirtf.zarr"), *IIRTF_ARGS, "--threads", "2"]) == 0
    return tiling, d


def test_info_json_reports_the_contract(built, cli):
    tiling, d = built
    code, out, err = cli("info", d / "svf.zarr", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["kind"] == "svf" and doc["resolution"] == [16, 16] and doc["components"] == 4
    ex = doc["exemplars"]
    assert [e["exemplar"] for e in ex] == [0, 1]
    assert sum(e["segments"] for e in ex) == doc["segments"] > 0
    assert all(e["bytes"] > 0 and 0 <= e["pca_sign_error"] < 0.2 for e in ex)
    code, out, err = cli("info", d / "iirtf.zarr", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["kind"] == "iirtf" and doc["order"] == 2 and doc["sh_coefficients"] == 9
    for e in doc["exemplars"]:
        assert e["mean_free_path"] > 0 and e["cells"] == e["cell_grid"][0] * e["cell_grid"][1] * e["cell_grid"][2]
        assert e["bytes"] > 0


def test_up_to_date_and_thread_count_independent_bytes(built, cli, tmp_path):
    tiling, d = built
    code, out, _ = cli("precompute", "svf", tiling, "-o", d / "svf.zarr", *SVF_ARGS)
    assert code == 0 and "up to date" in out
    code, out, _ = cli("precompute", "iirtf", tiling, "-o", d / "iirtf.zarr", *IIRTF_ARGS)
    assert code == 0 and "up to date" in out
    for kind, args in (("svf", SVF_ARGS), ("iirtf", IIRTF_ARGS)):
        one = tmp_path / f"{kind}1.zarr"
        code, _, err = cli("precompute", kind, tiling, "-o", one, *args, "--threads", "1")
        assert code == 0, err
        assert _arrays(one) == _arrays(d / f"{kind}.zarr"), kind


def test_inspect_pictures(built, cli, tmp_path):
    _, d = built
    seg = json.loads(cli("info", d / "svf.zarr", "--json")[1])["exemplars"][1]["segment_range"][0] + 7
    for args in ((d / "svf.zarr", "--segment", seg), (d / "iirtf.zarr", "--exemplar", 1)):
        png = tmp_path / "p.png"
        code, _, err = cli("inspect", *args, "--png", png)
        assert code == 0, err
        assert png.stat().st_size > 20000
    code, _, err = cli("inspect", d / "svf.zarr", "--segment", 10 ** 9, "--png", tmp_path / "q.png")
    assert code == 2 and "segment" in err


BAD = [
    (("svf",), ["--resolution", "4"], "resolution"),
    (("svf",), ["--resolution", "20"], "multiple of 8"),
    (("svf",), ["--components", "0"], "--components"),
    (("svf",), ["--exemplar", "7"], "exemplar 7"),
    (("iirtf",), ["--order", "-1"], "SH order"),
    (("iirtf",), ["--order", "9"], "SH order"),
    (("iirtf",), ["--cell-factor", "0"], "--cell-factor"),
    (("iirtf",), ["--cell-factor", "-2"], "--cell-factor"),
    (("iirtf",), ["--cell-factor", "nan"], "--cell-factor"),
    (("iirtf",), ["--scene", "no/such/scene.toml"], "not found"),
    (("iirtf",), ["--light-sampling", "best"], "estimator"),
    (("iirtf",), ["--light-domain", "below"], "light domain"),
    (("iirtf",), ["--layer-paths", "1"], "--layer-paths"),
    (("iirtf",), ["--layer-bins", "0"], "--layer-bins"),
    (("svf",), ["--threads", "0"], "--threads"),
    (("iirtf",), ["--threads", "-2"], "--threads"),
]


@pytest.mark.parametrize("sub,extra,needle", BAD)
def test_bad_input_exit_2_nothing_written(built, cli, tmp_path, sub, extra, needle):
    tiling, d = built
    base = SVF_ARGS if sub[0] == "svf" else [a for a in IIRTF_ARGS]
    if "--scene" in extra:
        i = base.index("--scene")
        base = base[:i] + base[i + 2:]
    fresh = tmp_path / "fresh.zarr"
    code, out, err = cli("precompute", *sub, tiling, "-o", fresh, *base, *extra)
    assert code == 2, (out, err)
    assert needle in err and len(err.strip().splitlines()) == 1, err
    assert not fresh.exists() and not list(tmp_path.glob(".fresh*"))
    existing = d / f"{sub[0]}.zarr"
    before = read_meta(existing)["content_hash"]
    code, _, err = cli("precompute", *sub, tiling, "-o", existing, *base, *extra, "--force")
    assert code == 2
    assert read_meta(existing)["content_hash"] == before


def test_wrong_kind_of_input(built, cli, tmp_path):
    _, d = built
    for sub, args in (("svf", SVF_ARGS), ("iirtf", IIRTF_ARGS)):
        code, _, err = cli("precompute", sub, d / "svf.zarr", "-o", tmp_path / "x.zarr", *args)
        assert code == 2 and "tiling" in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "x.zarr").exists()


@pytest.mark.parametrize("extra,needle", [(["--directions", "diagonal"], "--directions"),
                                          (["--light-coords", "polar"], "--light-coords"),
                                          (["--light-coords", "half", "--lights", "0x15"], "--lights"),
                                          (["--light-domain", "cube"], "--light-domain"),
                                          (["--light-domain", "sphere", "--light-coords", "half"], "--light-domain"),
                                          (["--plane", "bottom"], "--plane"),
                                          (["--lobes", "3"], "--lobes"),
                                          (["--threads", "-2"], "--threads"),   # was an internal error
                                          (["--model", "neural"], "--model"),
                                          (["--model", "tabulated", "--components", "0"], "--components"),
                                          # 2 x 2 texels + 1 x 1: 5 rows, rank bound 4
                                          (["--model", "tabulated", "--components", "5"], "rank bound"),
                                          (["--model", "tabulated", "--components", "2", "--clusters", "0"],
                                           "--clusters"),
                                          (["--model", "tabulated", "--components", "2", "--clusters", "6"],
                                           "--clusters")])
def test_btf_bad_options_exit_2_nothing_written(built, cli, tmp_path, extra, needle):
    """precompute btf: an unknown direction scheme, light coordinates, light domain, plane, lobe count or model, a light
    domain of both sides on half-vector cells, an empty light grid, a
    thread count below 1, a component count below 1 or above the table's rank bound, a cluster count below 1 or
    above the texels, is refused before any work: exit 2, one line naming the option, no artifact."""
    tiling, _ = built
    fresh = tmp_path / "fresh_btf.zarr"
    code, out, err = cli("precompute", "btf", tiling, "-o", fresh, "--resolution", "2", *extra)
    assert code == 2, (out, err)
    assert needle in err and len(err.strip().splitlines()) == 1, err
    assert not fresh.exists()


def test_cell_grid_does_not_depend_on_the_seed(built, cli, tmp_path):
    """Reference: the contract that ell is the exemplar's (pipeline/runners/precompute.py, MFP_SEED): the
    mean free path, its standard error and every exemplar's cell grid are the same at --seed 0 and --seed 5,
    while the transfer matrices (the seed's Monte Carlo) differ."""
    tiling, d = built
    other = tmp_path / "iirtf_seed5.zarr"
    code, _, err = cli("precompute", "iirtf", tiling, "-o", other, *IIRTF_ARGS, "--seed", "5")
    assert code == 0, err
    docs = []
    for path in (d / "iirtf.zarr", other):
        code, out, err = cli("info", path, "--json")
        assert code == 0, err
        docs.append(json.loads(out)["exemplars"])
    for a, b in zip(*docs):
        for key in ("mean_free_path", "mean_free_path_se", "free_paths", "cells", "cell_grid", "cell_size"):
            assert a[key] == b[key], key
    arrays = (_arrays(d / "iirtf.zarr"), _arrays(other))
    assert arrays[0]["exemplar_0/cell_row"] == arrays[1]["exemplar_0/cell_row"]
    assert arrays[0]["exemplar_0/transfer"] != arrays[1]["exemplar_0/transfer"]


BTF_ARGS = ["--resolution", "2", "--views", "2x4", "--lights", "2x4", "--spp", "2", "--max-depth", "3",
            "--scene", "data/scenes/draped_damask.toml"]


def test_btf_fits_every_exemplar_the_block_map_uses_each_as_alone(tiny_tiling, cli, tmp_path):
    """Contract (pipeline/runners/precompute_btf.py): without --exemplar, precompute btf fits every exemplar the
    tiling's block map uses (the tiny tiling's map uses both), each array with a leading exemplar axis in the
    summary's order; reference: each exemplar fitted alone (--exemplar K, on 1 thread) gives the same bytes as its
    slice of the joint artifact (2 threads): an exemplar's acquisition and fit depend neither on the others nor
    on the threads. Both pictures of
    ``loomlight inspect`` are drawn."""
    from pipeline.artifacts import Artifact

    tiling = tiny_tiling[0]
    both, one = tmp_path / "both.zarr", tmp_path / "one.zarr"
    code, out, err = cli("precompute", "btf", tiling, "-o", both, *BTF_ARGS, "--threads", "2")
    assert code == 0, err
    assert "2 exemplar(s)" in out
    code, _, err = cli("precompute", "btf", tiling, "-o", one, *BTF_ARGS, "--exemplar", "1", "--threads", "1")
    assert code == 0, err
    a, b = Artifact(both), Artifact(one)
    assert a.summary["exemplars"] == [0, 1] and a.summary["exemplar_names"] == ["plain", "satin"]
    assert b.summary["exemplars"] == [1] and b.summary["exemplar_names"] == ["satin"]
    assert [e["exemplar"] for e in a.summary["per_exemplar"]] == [0, 1]
    names = [n for n in a.arrays() if n.startswith("level_") or n in ("samples", "alpha")]
    assert "samples" in names and "level_1/rho" in names
    for n in names:
        x, y = np.asarray(a[n]), np.asarray(b[n])
        assert x.shape[0] == 2 and y.shape[0] == 1, n
        assert x[1].tobytes() == y[0].tobytes(), n
    assert not np.array_equal(np.asarray(a["samples"][0]), np.asarray(a["samples"][1]))
    from tests.inspector_checks import assert_legible_png

    for art in (both, one):         # a row per exemplar, or the two view/light pairs of the one
        png = tmp_path / f"{art.stem}.png"
        code, _, err = cli("inspect", art, "--png", png)
        assert code == 0, err
        assert_legible_png(png)


@pytest.mark.slow   # an acquisition, a fit, a table, a render and a picture: make test-all (make test's budget)
def test_btf_half_vector_cells_end_to_end(tiny_tiling, cli, tmp_path):
    """Contract (pipeline/runners/precompute_btf.py, stages/core/btf.py module doc): ``--light-coords half`` acquires
    on nx x ny half-vector cells (the samples' light axis), records them (``light_coords``, ``half_dirs``), fits the
    Lafortune lobes on the 8 x 8 hemisphere grid (``light_dirs``, ``fit_light_grid``); a cell that has no light
    from any view of a view cell (valid fraction 0: ``half_cell_geometry``) holds exactly 0 in every texel; the
    artifact renders with the tabulated model, and ``loomlight inspect`` draws it."""
    from pipeline.artifacts import Artifact
    from stages.core.btf import half_cell_geometry, hemisphere_grid
    from tests.inspector_checks import assert_legible_png

    tiling = tiny_tiling[0]
    path = tmp_path / "half.zarr"
    args = [a if a != "2x4" or i != BTF_ARGS.index("--lights") + 1 else "5x4" for i, a in enumerate(BTF_ARGS)]
    code, out, err = cli("precompute", "btf", tiling, "-o", path, *args, "--light-coords", "half", "--model",
                         "tabulated", "--clusters", "1", "--components", "2", "--threads", "2")
    assert code == 0, err
    a = Artifact(path)
    s = a.summary
    assert s["light_coords"] == "half" and s["light_grid"] == [5, 4] and s["fit_light_grid"] == [8, 8]
    assert np.asarray(a["half_dirs"]).shape == (20, 3)
    assert np.allclose(np.asarray(a["light_dirs"]), hemisphere_grid(8, 8))
    samples = np.asarray(a["samples"], np.float64)          # (2 exemplars, 2, 2, 8 views, 20 cells, 3)
    assert samples.shape == (2, 2, 2, 8, 20, 3)
    valid = half_cell_geometry(2, 4, 5, 4, True).valid
    assert (valid == 0).any() and np.any(samples[..., valid > 0, :] > 0)
    assert np.all(samples[..., valid == 0, :] == 0.0)
    scene = tmp_path / "scene.toml"
    scene.write_text(Path("data/scenes/flat_satin.toml").read_text())
    exr = tmp_path / "render.exr"
    code, _, err = cli("render", scene, "--method", "btf", "--source", "tiling", "--fibers", tiling, "--set",
                       f"btf={path}", "--set", "model=tabulated", "--width", "24", "--height", "18", "--spp", "1",
                       "-o", exr)
    assert code == 0, err
    png = tmp_path / "half.png"
    code, _, err = cli("inspect", path, "--png", png)
    assert code == 0, err
    assert_legible_png(png)


@pytest.mark.slow   # an acquisition, a fit, a table, a render and a picture: make test-all (make test's budget)
def test_btf_light_from_below_end_to_end(tiny_tiling, cli, tmp_path):
    """Contract (pipeline/runners/precompute_btf.py, stages/core/btf.py "Light from below"): ``--light-domain sphere``
    acquires the light grid and its mirror below the fabric (the samples' light axis twice the grid, recorded as
    ``light_domain``), fits the Lafortune lobes to the lights above alone (the same fit as a hemisphere acquisition
    given those samples: checked against ``fit_levels`` on the upper half), lets light through the tiny open weave
    (the lower half holds light), and its tabulated model renders a light from below that the fit leaves black;
    ``loomlight inspect`` draws it."""
    from pipeline.artifacts import Artifact
    from pipeline.images import read_exr
    from stages.core.btf import hemisphere_grid
    from stages.precompute.btf_fit import fit_levels
    from tests.inspector_checks import assert_legible_png

    tiling = tiny_tiling[0]
    path = tmp_path / "sphere.zarr"
    code, out, err = cli("precompute", "btf", tiling, "-o", path, *BTF_ARGS, "--light-domain", "sphere", "--model",
                         "tabulated", "--clusters", "1", "--components", "2", "--threads", "2")
    assert code == 0, err
    a = Artifact(path)
    s = a.summary
    assert s["light_domain"] == "sphere" and s["light_grid"] == [2, 4]
    assert np.allclose(np.asarray(a["light_dirs"]), hemisphere_grid(2, 4))
    samples = np.asarray(a["samples"], np.float32)          # (2 exemplars, 2, 2, 8 views, 16 lights, 3)
    assert samples.shape == (2, 2, 2, 8, 16, 3)
    assert np.any(samples[..., 8:, :] > 0)
    frames = np.asarray(a["level_0/frame"], np.float64)
    ref = fit_levels(samples[0, :, :, :, :8], np.asarray(a["alpha"])[0], frames[0], np.asarray(a["view_dirs"]),
                     hemisphere_grid(2, 4), 2, 0.1, max_rounds=10)
    assert np.allclose(ref[0].rho.reshape(2, 2, 3), np.asarray(a["level_0/rho"])[0], rtol=1e-6, atol=1e-7)
    scene = tmp_path / "scene.toml"
    text = Path("data/scenes/flat_satin.toml").read_text()   # its yarns; the tiny tiling's 0.2 x 0.2 patch in view,
    scene.write_text(text.split("[camera]")[0] + "[camera]\norigin = [0.1, -0.1, 0.5]\ntarget = [0.1, 0.1, 0.0]\n"
                     "fov = 30.0\n\n[[lights]]\ntype = \"directional\"\ndirection = [0.2, 0.3, 0.9]\n"  # from below
                     "irradiance = 3.0\n\n[render]" + text.split("[render]")[1])
    exr = tmp_path / "render.exr"
    sums = {}
    for model in ("tabulated", "lafortune"):
        code, _, err = cli("render", scene, "--method", "btf", "--source", "tiling", "--fibers", tiling, "--set",
                           f"btf={path}", "--set", f"model={model}", "--width", "24", "--height", "18", "--spp", "1",
                           "-o", exr)
        assert code == 0, err
        rgb, ch = read_exr(exr)
        assert (ch["A"] > 0).mean() > 0.5
        sums[model] = float(rgb[ch["A"] > 0].sum())
    assert sums["tabulated"] > 0.0 and sums["lafortune"] == 0.0, sums
    png = tmp_path / "sphere.png"
    code, _, err = cli("inspect", path, "--png", png)
    assert code == 0, err
    assert_legible_png(png)


@pytest.mark.slow   # three acquisitions and the table's kernels: kept out of make test's budget (make test-all)
def test_btf_tabulated_reuses_the_acquisition(tiny_tiling, cli, tmp_path):
    """Contract (pipeline/runners/precompute_btf.py, stages/precompute/btf_compress.py): ``--model tabulated`` on an
    artifact acquired with the same acquisition parameters reuses its samples (said on the output) and adds the
    compressed table; the Lafortune fit stays byte-identical to the one made without the table; the table's error
    never rises with the component count and its last entry is the recorded error of the stored table (its bytes
    on 1 and 2 threads: tests/precompute/test_btf_compress.py). ``loomlight inspect`` draws the table beside the
    fit and the error curve."""
    from pipeline.artifacts import Artifact

    tiling = tiny_tiling[0]
    path = tmp_path / "tex.zarr"
    code, out, err = cli("precompute", "btf", tiling, "-o", path, *BTF_ARGS, "--threads", "2")
    assert code == 0, err
    before = Artifact(path)
    fit = {n: np.asarray(before[n]).tobytes() for n in before.arrays() if n.startswith("level_") or n == "samples"}
    tab = ["--model", "tabulated", "--clusters", "2", "--components", "3"]
    code, out, err = cli("precompute", "btf", tiling, "-o", path, *BTF_ARGS, *tab, "--threads", "2")
    assert code == 0, err
    assert "acquisition reused" in out and "tabulated" in out
    a = Artifact(path)
    assert a.summary["acquisition_reused"] and a.summary["models"] == ["lafortune", "tabulated"]
    for n, b in fit.items():
        assert np.asarray(a[n]).tobytes() == b, n
    curve = np.asarray(a["tabulated/rel_rmse_by_components"])
    assert curve.shape == (2, 4)
    assert np.all(np.diff(curve, axis=1) <= 1e-12)
    for e in range(2):
        assert abs(curve[e, -1] - a.summary["per_exemplar"][e]["table_rel_rmse"]) <= 1e-5 * max(curve[e, 0], 1e-12)
    reused = {n: np.asarray(a[n]).tobytes() for n in a.arrays() if n.startswith(("tabulated/", "level_", "samples"))}
    code, out, err = cli("precompute", "btf", tiling, "-o", path, *BTF_ARGS, *tab, "--threads", "2", "--force")
    assert code == 0, err
    assert "acquisition reused" not in out                      # --force acquires again: the same bytes
    again = Artifact(path)
    for n, b in reused.items():
        assert np.asarray(again[n]).tobytes() == b, n
    from tests.inspector_checks import assert_legible_png

    png = tmp_path / "tex.png"
    code, _, err = cli("inspect", path, "--png", png)
    assert code == 0, err
    assert_legible_png(png)


@pytest.mark.slow   # an acquisition, a fit, a render and a picture: make test-all (make test's budget)
def test_btf_relief_end_to_end(tiny_tiling, cli, tmp_path):
    """Contract (pipeline/runners/precompute_btf.py ``relief_heights``, stages/render/integrators/btf.py "Relief"):
    ``--plane relief`` writes a height per texel and exemplar (``heights``, within the exemplars' slab; the surface
    plane as ``plane_z``), the btf renderer reads it by relief mapping (the picture differs from the same texture
    read on its surface plane, ``--set relief=off``), and ``loomlight inspect`` draws the heights."""
    from pipeline.artifacts import Artifact
    from pipeline.images import read_exr
    from tests.inspector_checks import assert_legible_png

    tiling = tiny_tiling[0]
    path = tmp_path / "texture.zarr"
    code, out, err = cli("precompute", "btf", tiling, "-o", path, *BTF_ARGS, "--plane", "relief", "--threads", "2")
    assert code == 0, err
    a = Artifact(path)
    s = a.summary
    h = np.asarray(a["heights"], np.float64)
    assert s["plane"] == "relief" and h.shape == (2, 2, 2)
    assert np.all((h >= s["bottom"] - 1e-6) & (h <= s["top"] + 1e-6)) and s["bottom"] < s["plane_z"] < s["top"]
    scene = tmp_path / "scene.toml"
    text = Path("data/scenes/flat_satin.toml").read_text()
    scene.write_text(text.split("[camera]")[0] + "[camera]\norigin = [0.1, -0.1, 0.5]\ntarget = [0.1, 0.1, 0.0]\n"
                     "fov = 30.0\n\n[[lights]]\ntype = \"directional\"\ndirection = [-0.2, 0.3, -0.9]\n"
                     "irradiance = 3.0\n\n[render]" + text.split("[render]")[1])
    pictures = []
    for name in ("on", "off"):      # off: the same texture read where the ray crosses the surface (one plane)
        exr = tmp_path / f"relief_{name}.exr"
        code, _, err = cli("render", scene, "--method", "btf", "--source", "tiling", "--fibers", tiling, "--set",
                           f"btf={path}", "--set", f"relief={name}", "--width", "24", "--height", "18", "--spp", "1",
                           "-o", exr)
        assert code == 0, err
        rgb, ch = read_exr(exr)
        assert (ch["A"] > 0).mean() > 0.5
        pictures.append(rgb)
    assert not np.array_equal(pictures[0], pictures[1])
    png = tmp_path / "relief.png"
    code, _, err = cli("inspect", path, "--png", png)
    assert code == 0, err
    assert_legible_png(png)
