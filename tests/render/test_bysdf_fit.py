"""``loomlight fit-bysdf`` (seed 004 §5's protocol against fiberpath on the realized fibres of the same yarns).

Reference: fiberpath renders of the realized fibres under the front, back and front+back lights. The fit must
move the front and back mean luminance towards the reference (or report the energy cap that stops it), and
write parameters that bysdf reads back. Slow: it realizes fibres and renders fiberpath and bysdf several
times (make test-all).
"""
import math
import tomllib

import numpy as np
import pytest

from tests.render.test_bysdf_render import _make, _weave


@pytest.mark.slow
def test_fit_moves_bysdf_towards_fiberpath(tmp_path, cli):
    from pipeline.runners.fit_bysdf import SETUPS, run_fit
    from pipeline.runners.realize import run_realize

    scene, yarns = _make(tmp_path, "fit", _weave(2, L=0.2), origin=(0.05, -0.2, 0.3), w=24, h=18)
    fibers = tmp_path / "fit" / "fibers.zarr"
    run_realize(yarns, fibers)
    out = tmp_path / "fit" / "params.toml"
    rep = run_fit(scene.path, yarns, fibers, out, width=24, height=18, spp=8, ref_spp=16, iterations=3,
                  progress=lambda *_: None)
    first = rep["history"][0]
    final = rep["setups"]
    for n in SETUPS:
        assert math.isfinite(final[n]["rel_error_luminance"])
    if not rep["energy_capped"]:
        assert abs(final["front"]["rel_error_luminance"]) < abs(first["front_rel_error"]) + 0.02
        assert abs(final["back"]["rel_error_luminance"]) < abs(first["back_rel_error"]) + 0.02
    got = tomllib.loads(out.read_text())["default"]
    assert 0.0 <= got["spec_weight"] <= 1.0 and 0.0 <= got["reflect_weight"] <= 1.0
    assert (tmp_path / "fit" / "params.json").exists()
    code, _, err = cli("render", str(scene.path), "--method", "bysdf", "--set", f"yarns={yarns}", "--set",
                       f"params={out}", "--spp", "1", "-o", str(tmp_path / "fit" / "fitted.exr"))
    assert code == 0, err


def test_fit_recovers_known_colours_from_a_synthetic_target(tmp_path):
    """Reference: a synthetic target with known answers -- bysdf itself rendered with a known energy split
    and per-channel colour factors, under the fit's front and back lights (same seed, so the fitted renders
    see the same random numbers). From the defaults, the fit's rounds bring the front and back means within
    1 % per channel of the target and recover the colour factors' chromaticity within 3 % and each side's
    energy times their level within 5 %."""
    from pipeline.runners.fit_bysdf import FitState, _Renderer, bysdf_means, fit_rounds, setup_lights

    scene, yarns = _make(tmp_path, "synthetic", _weave(2, L=0.2), origin=(0.05, -0.2, 0.3), w=24, h=18)
    lights = setup_lights(scene)
    by = _Renderer(scene, "bysdf", {"width": 24, "height": 18, "spp": 64, "seed": 3}, {"yarns": yarns})
    _, render_means = bysdf_means(by, yarns, lights)
    known = FitState(0.35, 0.3, np.array([0.6, 1.0, 1.3]), np.array([1.2, 0.8, 0.9]))
    target = render_means(known, ("front", "back"))
    fit, history = fit_rounds(render_means, target, FitState(0.25, 0.25), 10, progress=lambda *_: None)
    got = render_means(fit, ("front", "back"))
    for n in ("front", "back"):
        np.testing.assert_allclose(got[n], target[n], rtol=0.01, err_msg=n)
    # a side's brightness is its body energy times its colour factors' level (x s and y s render alike), and
    # two means per channel cannot tell the uncoloured specular share from the body's level (measured: the
    # fit ends at spec_weight 0.415 for the known 0.35, the transmission factors' chromaticity 1-2 % off,
    # identical means): recovered are the factors' chromaticity within 3 % and the energy-weighted level
    luma = np.array([0.2126, 0.7152, 0.0722])
    for e, s, e0, s0 in ((fit.x, fit.scale_r, known.x, known.scale_r), (fit.y, fit.scale_t, known.y, known.scale_t)):
        np.testing.assert_allclose(s / (luma @ s), s0 / (luma @ s0), rtol=0.03)
        assert e * (luma @ s) == pytest.approx(e0 * (luma @ s0), rel=0.05)
    first = max(abs(v) for k, v in history[0].items() if k.endswith("_rel_error"))
    assert first > 0.05          # the defaults start away from the target
