"""``loomlight fit-bysdf`` (seed 004 §5's protocol against fiberpath on the realized fibres of the same yarns).

Reference: fiberpath renders of the realized fibres under the front, back and front+back lights. The fit must
move the front and back mean luminance towards the reference (or report the energy cap that stops it), and
write parameters that bysdf reads back. Slow: it realizes fibres and renders fiberpath and bysdf several
times (make test-all).
"""
import math
import tomllib

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
