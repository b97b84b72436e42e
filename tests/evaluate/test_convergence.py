"""The equal-error comparison (stages/evaluate/convergence.py, pipeline/runners/convergence.py,
``loomlight evaluate --convergence``).

References, per test:
- the fit: synthetic E^2 = b^2 + c/t with known b, c and Gaussian scatter of known size (recovered
  within 3 of the fit's standard errors);
- the reference-noise subtraction: synthetic pictures with known truth, reference noise of known
  variance and batches drawn from it; the mean of E^2 over many trials against the known squared bias;
- two independent renders of one method: a stand-in renderer (registered only here) whose picture is a
  known image plus Gaussian noise of variance sigma^2 / spp per pixel, its time proportional to spp;
  an unbiased stand-in's floor is consistent with zero, a biased one's is its known bias;
- equal-time budgets: the stand-in's time per spp is known, so the strip's spp are exact;
- bad input: one line naming the file and the key, exit code 2.
"""
import json
import math

import numpy as np
import pytest
import zarr

from pipeline.errors import LoomError
from pipeline.images import write_render
from stages.evaluate import convergence as cv
from tests.evaluate.test_sweep import SCENE as SWEEP_SCENE
from tests.helpers import DATA

# ------------------------------------------------------------------------------------------------
# the fit


@pytest.mark.parametrize("b,c", [(0.12, 0.4), (0.0, 0.9), (0.3, 0.02)])
def test_fit_recovers_bias_and_noise(b, c):
    rng = np.random.default_rng(1)
    t = 0.05 * 2.0 ** np.arange(9)
    truth = b * b + c / t
    se = 0.03 * truth
    e2 = truth + rng.normal(0.0, se)
    fit = cv.fit_bias_noise(t, e2, se)
    assert abs(fit.b2 - b * b) <= 3 * fit.b2_se + 1e-12
    assert abs(fit.c - c) <= 3 * fit.c_se
    assert fit.floor == pytest.approx(b, abs=max(3 * fit.floor_se, 0.02))


def test_fit_keeps_parameters_non_negative():
    t = np.array([1.0, 2.0, 4.0, 8.0])
    fit = cv.fit_bias_noise(t, [0.038, 0.039, 0.040, 0.041], [0.001] * 4)   # error grows with time: c fixed at 0
    assert fit.c == 0.0 and fit.b2 == pytest.approx(0.0395, rel=0.02)
    fit = cv.fit_bias_noise(t, 0.5 / t - 0.01, 0.01 * 0.5 / t)                # a negative floor: b^2 fixed at 0
    assert fit.b2 == 0.0 and fit.c == pytest.approx(0.5, rel=0.1)
    assert fit.b2_se > 0.0          # held at 0, the floor still carries the free fit's uncertainty


def test_time_to_error_uses_measured_points():
    t = np.array([1.0, 2.0, 4.0, 8.0])
    fit = cv.NoiseFit(0.0, 0.04, 0.0, 0.0, 4)               # E = 0.2 / sqrt(t)
    e = np.sqrt(fit.e2(t))
    tt = cv.time_to_error(0.1, t, e, fit)                   # 0.2/sqrt(t) = 0.1 at t = 4, a measured point
    assert tt.bound == "" and tt.time == pytest.approx(4.0)
    tt = cv.time_to_error(0.12, t, e, fit)                  # interpolated by the fit inside (2, 4)
    assert tt.bound == "" and tt.time == pytest.approx(0.04 / 0.0144)
    assert cv.time_to_error(0.01, t, e, fit).bound == ">"   # not reached by the last point
    assert cv.time_to_error(0.5, t, e, fit).bound == "<="   # reached at the first budget
    floored = cv.NoiseFit(0.04, 0.04, 0.0, 0.0, 4)
    assert cv.time_to_error(0.15, t, np.sqrt(floored.e2(t)), floored).floor_blocks


# ------------------------------------------------------------------------------------------------
# the reference-noise subtraction

def _truth(h=24, w=32, seed=0):
    rng = np.random.default_rng(seed)
    base = 0.2 + 0.8 * rng.random((h, w, 1)) * np.array([1.0, 0.8, 0.5])
    alpha = np.ones((h, w))
    alpha[:, :4] = 0.0   # background columns are not cloth
    return base, alpha


def test_reference_noise_subtraction_is_unbiased():
    truth, alpha = _truth()
    rng = np.random.default_rng(7)
    bias = 0.05                                          # the test is truth x (1 + 0.05): E^2 = 0.05^2 x known factor
    test = truth * (1.0 + bias)
    mask = alpha > 0.5
    d = cv.denominators(truth, mask)
    expected = float(np.mean(((test - truth) ** 2).mean(axis=2)[mask] / d[mask] ** 2))
    K, sigma = 8, 0.08                                   # batch noise: 8 % of the pixel per batch
    corrected, raw, ses = [], [], []
    for _ in range(200):
        batches = truth[None] * (1.0 + sigma * rng.standard_normal((K,) + truth.shape))
        st = cv.batch_mean(batches)
        pe = cv.relative_error(test, st.mean, st.variance, alpha, K)
        corrected.append(pe.e2)
        raw.append(pe.raw_e2)
        ses.append(pe.e2_se)
    corrected, raw = np.array(corrected), np.array(raw)
    sem = corrected.std(ddof=1) / math.sqrt(len(corrected))
    # the denominators come from the noisy reference itself: a bias of order sigma^2 / K relative, ~0.1 %
    assert abs(corrected.mean() - expected) < 3 * sem + 0.02 * expected
    assert raw.mean() - expected > 20 * sem                 # without the subtraction: far off
    assert np.mean(ses) == pytest.approx(corrected.std(ddof=1), rel=0.5)   # the stated uncertainty is honest


def test_batch_mean_variance_of_the_mean():
    rng = np.random.default_rng(3)
    x = rng.normal(2.0, 0.5, (16, 40, 50, 3))
    st = cv.batch_mean(x)
    assert st.variance.mean() == pytest.approx(0.25 / 16, rel=0.05)
    with pytest.raises(ValueError):
        cv.batch_mean(x[:1])


def test_equal_time_spp():
    assert cv.equal_time_spp(1.6, 0.1) == 16
    assert cv.equal_time_spp(1.6, 0.004) == 400
    assert cv.equal_time_spp(0.01, 1.0) == 1
    with pytest.raises(ValueError):
        cv.equal_time_spp(1.0, 0.0)


# ------------------------------------------------------------------------------------------------
# the whole comparison with a stand-in renderer

SCENE = SWEEP_SCENE   # a small woven scene under a constant light: the stand-in reads only its camera and [render]

COMPARE = """
[compare]
name = "unit"
scene = "scene.toml"
reference = "exact"
camera = {{ width = 32, height = 24 }}
levels = [0.3, 0.1, 0.05]
equal_time_spp = 16

[reference]
spp = 64
batches = 8
max_batches = 64

[[methods]]
name = "exact"
method = "standin"
render = {{ source = "procedural" }}
budgets = [1, 2, 4, 8, 16, 32, 64]

[[methods]]
name = "fast"
method = "standin"
render = {{ source = "realized" }}
budgets = {fast_budgets}
target_speedup = 4.0
"""

SIGMA = 0.6                         # per-sample relative noise of the stand-in
SECONDS_PER_SPP = {"procedural": 0.01, "realized": 0.001}
BIAS = {"procedural": 0.0, "realized": 0.08}   # the realized stand-in is 8 % bright everywhere
TAIL = 0.1                          # the stand-in's light beyond depth d: TAIL ** d of it (1 - TAIL ** d kept)


def _standin_method():
    from pipeline.renderers import RenderMethod, Source

    return RenderMethod("standin", "closed-form stand-in", "standin",
                        sources=tuple(Source(s, (), s) for s in SECONDS_PER_SPP), default_source="procedural")


@pytest.fixture
def standin(monkeypatch, request):
    """Register the stand-in render method; returns the renderer the runner calls and the calls made."""
    from pipeline.renderers import METHODS
    from pipeline.scene import load_scene
    from pipeline.schemas import load_schema

    monkeypatch.setitem(METHODS, "standin", _standin_method())
    # the scene schema lists the registry's methods and is cached: built again with the stand-in, and without it
    # after (a cache filled here named "standin" to every later test of this process: docs --check saw it)
    load_schema.cache_clear()
    request.addfinalizer(load_schema.cache_clear)
    calls = []

    def render(scene_file, method, exr, args):
        sc = load_scene(scene_file)
        h, w = sc.camera["height"], sc.camera["width"]
        spp, seed, src = sc.render["spp"], sc.render["seed"], sc.render["source"]
        truth, alpha = _truth(h, w)
        rng = np.random.default_rng(seed * 7919 + spp)
        noise = SIGMA / math.sqrt(spp) * rng.standard_normal(truth.shape)
        kept = 1.0 - TAIL ** sc.render["max_depth"]
        rgb = (truth * kept * (1.0 + BIAS[src]) * (1.0 + noise)).astype(np.float32)
        write_render(exr, rgb, {"A": alpha.astype(np.float32)})
        g = zarr.open_group(str(exr.with_suffix(".zarr")), mode="w", zarr_format=3)
        g.attrs["summary"] = {"kind": "render", "render_time_s": SECONDS_PER_SPP[src] * spp, "spp": spp,
                              "width": w, "height": h, "paths": spp * w * h, "method_stats": {"geometry_bytes": 1000}}
        g.attrs["loomlight"] = {"kind": "render", "complete": True}
        calls.append((src, spp, seed))
    return render, calls


@pytest.fixture
def compare_file(tmp_path):
    (tmp_path / "scene.toml").write_text(SCENE)
    p = tmp_path / "compare.toml"
    p.write_text(COMPARE.format(fast_budgets="[1, 2, 4, 8, 16, 32, 64, 128]"))
    return p


def test_comparison_end_to_end(compare_file, tmp_path, standin):
    from pipeline.runners.convergence import run_convergence

    render, calls = standin
    out = tmp_path / "out"
    res = run_convergence(compare_file, out, renderer=render, echo=lambda s: None)
    # the reference: batches until the median pixel error is within 5 % (sigma 0.6 per sample: ~144 spp)
    ref = res.reference
    assert ref["pixel_error_p50"] <= 0.05 and ref["mean_error"] <= 0.002 and ref["targets_met"]
    ref_seeds = {s for src, spp, s in calls if spp == 64 and s >= 1_000_000}
    assert len(ref_seeds) == ref["batches"] >= 8
    assert not ref_seeds & {s for _, _, s in calls if s < 1_000_000}     # runs never reuse a batch's seed
    exact, fast = res.methods["exact"], res.methods["fast"]
    # two independent renders of one method: the unbiased stand-in's floor is consistent with zero
    assert exact["floor"] <= 3 * exact["floor_se"] + 0.01
    # the biased one's floor is its bias: E^2 -> 0.08^2 x mean (truth / d)^2 over cloth pixels
    truth, alpha = _truth(24, 32)
    mask = alpha > 0.5
    b_true = math.sqrt(float(np.mean((0.08 * truth).__pow__(2).mean(axis=2)[mask]
                                     / cv.denominators(truth, mask)[mask] ** 2)))
    assert fast["floor"] == pytest.approx(b_true, abs=3 * fast["floor_se"] + 0.005)
    # noise constants: E^2 = sigma^2 x mean (t_c / d)^2 / spp = c / t with t = SECONDS_PER_SPP x spp
    m2 = float(np.mean((truth ** 2).mean(axis=2)[mask] / cv.denominators(truth, mask)[mask] ** 2))
    assert exact["noise_constant"] == pytest.approx(SIGMA ** 2 * m2 * 0.01, rel=0.25)
    assert fast["noise_constant"] == pytest.approx(SIGMA ** 2 * m2 * 1.08 ** 2 * 0.001, rel=0.25)
    # at 30 % both reach it and fast is ~10x faster; at 5 % fast's floor (~8 %) blocks it
    assert fast["levels"]["0.05"]["floor_blocks"] and fast["levels"]["0.05"]["bound"] == ">"
    sp = fast["speedup"]["0.1"]
    assert sp["value"] is not None and 3.0 < sp["value"] < 30.0
    assert res.targets[0]["method"] == "fast" and res.targets[0]["target"] == 4.0
    # the equal-time strip: what was asked (16 spp of the reference method's time)
    doc = json.loads((out / "convergence.json").read_text())
    strip = doc["equal_time"]
    assert strip["exact"]["spp"] == 16 and strip["fast"]["spp"] == 160
    assert strip["fast"]["time_s"] == pytest.approx(strip["fast"]["asked_time_s"], rel=1e-6)
    for f in ("report.md", "report.html", "convergence.png", "equal_time.png", "reference/reference.exr",
              "reference/reference_error.png"):
        assert (out / f).stat().st_size > 0, f
    md = (out / "report.md").read_text()
    assert "bias floor" in md and "fastest" in md and "Equal time" in md
    from pipeline.artifacts import Artifact

    art = Artifact(out / "evaluation.zarr", kind="evaluation")
    assert art.summary["mode"] == "convergence" and art["error"].shape == (2, 8)
    from pipeline.inspectors import inspector_for

    png = tmp_path / "inspect.png"
    inspector_for("evaluation").inspect(art, png)          # loomlight inspect draws it
    assert png.stat().st_size > 10_000

    # a second run reuses the reference and every render
    n = len(calls)
    res2 = run_convergence(compare_file, out, renderer=render, echo=lambda s: None)
    assert len(calls) == n and res2.reference["reused"] and res2.rendered == 0


def test_reference_from_another_scene_or_code_is_refused(compare_file, tmp_path, standin, monkeypatch):
    from pipeline.runners import convergence as rc

    render, _ = standin
    out = tmp_path / "out"
    rc.run_convergence(compare_file, out, reference_only=True, renderer=render, echo=lambda s: None)
    ref = rc.default_reference_path(out)
    other = tmp_path / "other.toml"
    other.write_text(compare_file.read_text().replace("width = 32, height = 24", "width = 32, height = 24, fov = 30.0"))
    with pytest.raises(LoomError) as e:
        rc.run_convergence(other, out, ref_path=ref, renderer=render, echo=lambda s: None)
    assert e.value.file == str(ref) and e.value.place == "summary.reference.key.scene"
    monkeypatch.setattr(rc, "render_code_version", lambda method=None: "0123456789abcdef")
    with pytest.raises(LoomError) as e:
        rc.run_convergence(compare_file, out, ref_path=ref, renderer=render, echo=lambda s: None)
    assert e.value.place == "summary.reference.key.code" and "another code version" in e.value.message


@pytest.mark.parametrize("edit,place,words", [
    (("scene.toml", "nowhere.toml"), "compare.scene", "not found"),
    (('method = "standin"\nrender = { source = "realized" }',
      'method = "pathtracer"\nrender = { source = "realized" }'),
     "methods[1].method", "unknown render method"),
    (("target_speedup = 4.0", 'budget = "seconds"\ntarget_speedup = 4.0'), "methods[1].budget", "unknown budget"),
    (("[1, 2, 4, 8, 16, 32, 64, 128]", "[1, 2, 8, 4]"), "methods[1].budgets[3]", "must increase"),
    (("[1, 2, 4, 8, 16, 32, 64, 128]", "[0, 2]"), "methods[1].budgets[0]", "positive"),
    (('reference = "exact"', 'reference = "fibres"'), "compare.reference", "is not one of the methods"),
])
def test_bad_comparison_files(compare_file, tmp_path, standin, cli, edit, place, words):
    compare_file.write_text(compare_file.read_text().replace(*edit, 1))
    code, out, err = cli("evaluate", "--convergence", compare_file, "-o", tmp_path / "out")
    assert code == 2
    line = err.strip().splitlines()[-1]
    assert str(compare_file) in line and place in line and words in line, line
    assert "Traceback" not in err and not (tmp_path / "out" / "reference").exists()


def test_crossover_is_where_the_times_are_equal():
    """The closed form of convergence_report.crossover against the two fits' times at that error."""
    from pipeline.runners.convergence_report import crossover

    ref = {"b2": 0.0, "noise_constant": 0.6}
    biased = {"b2": 0.3 ** 2, "noise_constant": 0.1}          # less noise, more bias: faster at large errors
    how, e = crossover(biased, ref)
    t = lambda s, e: s["noise_constant"] / (e * e - s["b2"])  # noqa: E731
    assert how == "above" and t(biased, e) == pytest.approx(t(ref, e))
    assert t(biased, 1.2 * e) < t(ref, 1.2 * e) and t(biased, 0.95 * e) > t(ref, 0.95 * e)
    assert crossover({"b2": 0.0, "noise_constant": 0.1}, ref) == ("always", None)
    assert crossover({"b2": 0.01, "noise_constant": 0.9}, ref) == ("never", None)


@pytest.mark.parametrize("path", sorted((DATA / "compare").glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_comparison_files_load(path):
    """Every data/compare/*.toml is a valid comparison: its scene, methods, budgets and reference."""
    from pipeline.runners.compare_file import load_comparison

    cmp = load_comparison(path)
    assert cmp.reference in {m.name for m in cmp.methods}
    assert all(len(m.budgets) >= 3 for m in cmp.methods)


def test_reference_short_of_its_targets_is_extended(compare_file, tmp_path, standin):
    """A reference stopped by max_batches before its targets is reused as it is by a comparison, and
    extended (its batches kept, more rendered) by --reference-only once max_batches allows more."""
    from pipeline.runners import convergence as rc

    render, calls = standin
    out = tmp_path / "out"
    compare_file.write_text(compare_file.read_text().replace("max_batches = 64", "max_batches = 8")
                            .replace("spp = 64\nbatches", "spp = 8\nbatches"))    # 64 spp in all: ~7 % per pixel
    first = rc.run_convergence(compare_file, out, reference_only=True, renderer=render, echo=lambda s: None)
    assert first.reference["batches"] == 8 and not first.reference["targets_met"]
    compare_file.write_text(compare_file.read_text().replace("max_batches = 8", "max_batches = 64"))
    n = len(calls)
    again = rc.run_convergence(compare_file, out, reference_only=True, renderer=render, echo=lambda s: None)
    new_seeds = {s for _, _, s in calls[n:]}
    assert again.reference["targets_met"] and again.reference["batches"] > 8
    assert min(new_seeds) == 1_000_000 + 8             # the first eight batches were reused, not re-rendered


@pytest.mark.parametrize("depth", [1, 5])
def test_reference_depth_check_finds_the_light_its_depth_cuts(compare_file, tmp_path, standin, depth):
    """The reference's depth check: batch 0 again at 4x the depth, on the same random numbers, measures the share
    of the light the depth keeps exactly (the stand-in keeps 1 - 0.1^d); a depth that loses more than the mean
    error target (0.2 %) is flagged, printed and reported; a deep enough one is not."""
    from pipeline.runners import convergence as rc

    render, calls = standin
    deep = f"equal_time_spp = 16\nrender = {{ max_depth = {depth} }}"
    compare_file.write_text(compare_file.read_text().replace("equal_time_spp = 16", deep))
    said = []
    res = rc.run_convergence(compare_file, tmp_path / "out", reference_only=True, renderer=render, echo=said.append)
    dc = res.reference["depth_check"]
    want = (1.0 - TAIL ** depth) / (1.0 - TAIL ** (4 * depth))
    assert dc["max_depth"] == depth and dc["check_depth"] == 4 * depth
    assert dc["kept_rgb"] == pytest.approx([want] * 3, rel=1e-5)
    assert dc["truncated"] == (depth == 1)
    assert any(("TRUNCATED" in line) == (depth == 1) and "path depth" in line for line in said)
    from pipeline.runners.convergence_report import depth_sentence

    assert ("truncated" in depth_sentence(dc)) == (depth == 1)


def test_reference_made_before_its_folder_exists_is_reused(compare_file, tmp_path, standin):
    """make demo's order: ``--reference-only`` into a folder not yet there, then the whole comparison. An
    input named ``{out}/../x`` (make demo's artifacts beside the comparison's folder) names the same file
    before and after the folder exists, so the reference's input key matches and it is reused (it was
    refused: ``Path.exists`` of ``out/../x`` is False while ``out`` is missing, so the first run hashed no input)."""
    from pipeline.runners import convergence as rc

    render, calls = standin
    (tmp_path / "inputs.txt").write_text("an input artifact")
    compare_file.write_text(compare_file.read_text().replace(
        'name = "exact"\nmethod = "standin"',
        'name = "exact"\nmethod = "standin"\nargs = ["--fibers", "{out}/../inputs.txt"]'))
    out = tmp_path / "compare"
    assert not out.exists()
    rc.run_convergence(compare_file, out, reference_only=True, renderer=render, echo=lambda s: None)
    res = rc.run_convergence(compare_file, out, renderer=render, echo=lambda s: None)
    assert res.reference["reused"]


def test_a_methods_code_version_covers_what_its_renderer_reaches():
    """The reference's code key is the method's own code: fiberpath's covers its integrator, the shell and
    BVH walks, the colour curves and their lookup, and none of bysdf, prt or btf, whose work must not make
    fiberpath's converged references stale; bysdf's covers its own model."""
    from pipeline.source_graph import ROOT, render_code_files

    def rel(method):
        return {str(f.relative_to(ROOT)) for f in render_code_files(method)}

    every, fibres, yarns = rel(None), rel("fiberpath"), rel("bysdf")
    assert fibres < every and yarns < every
    for f in ("stages/render/integrators/fiberpath.py", "stages/core/shell/traversal.py",
              "stages/core/geometry/bvh.py", "pipeline/dye.py", "data/bcsdf/albedo_curves.json",
              "pipeline/renderers/fiberpath.py"):
        assert f in fibres, f
    assert not {f for f in fibres if "bysdf" in f or f.startswith("stages/precompute") or "btf" in f}
    assert "stages/core/shading/bysdf.py" in yarns and "stages/render/integrators/fiberpath.py" not in yarns
    assert not any(f.startswith("stages/evaluate") for f in every)
