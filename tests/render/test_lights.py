"""Distant lights (stages/render/lights.py): chi-square of every sampler through the light adapter
(tests/chisquare.py: check_light), closed-form normalisations, Mitsuba's lat-long orientation, the scene
packer; the harness itself. (The Lambertian sampler is tested in tests/core/shading/test_lambert.py.)"""
import math

import numpy as np
import pytest

from stages.render import lights as Lt
from tests.chisquare import (
    check_light,
    chi2_test,
    directions_to_xy,
    light_draw,
    light_eval_many,
    light_pdf_many,
    xy_to_directions,
)

_pdf = light_pdf_many   # the adapter's compiled loops, shared with the closed-form tests below
_eval = light_eval_many


def _setup(rows, img=None):
    env, marg, cond = Lt.envmap_tables(img)
    return np.asarray(rows), env, marg, cond


SPHERE = ((-1.0, 1.0), (-math.pi, math.pi))


@pytest.mark.parametrize("kind,sharpness", [("constant", 0.0), ("sg", 0.5), ("sg", 10.0), ("sg", 80.0)])
def test_sampling_chi2_sphere(kind, sharpness):
    """Reference: the light adapter: the sampled value equals light_eval and the pdf light_pdf (first 2000
    samples), then the chi-square of 200k samples against light_pdf integrated over (cos theta, phi) bins
    about the lobe axis."""
    axis = np.array([0.3, -0.5, 0.8])
    L, env, marg, cond = _setup([Lt.pack_light(kind, [1.0, 2.0, 3.0], axis, sharpness)])
    res = check_light(L, 0, env, marg, cond, axis=axis, n=200_000, seed=5, res=(100, 40), alpha=0.01, n_tests=5)
    assert res.passed, res.message


@pytest.mark.parametrize("sharpness", [0.01, 1.0, 30.0, 2000.0])
def test_sg_power_is_radiance_integral(sharpness):
    """Reference: 'power' = int L dw (scene schema); quadrature in cos theta about the axis."""
    axis = np.array([0.0, 1.0, 0.0])
    L, env, marg, cond = _setup([Lt.pack_light("sg", [2.0, 2.0, 2.0], axis, sharpness)])
    # substitution c = 1 - x: the lobe exp(lambda (c - 1)) is resolved by geometric spacing near c = 1
    x = np.concatenate([[0.0], np.geomspace(1e-9, 2.0, 20001)])
    c = 1.0 - x
    Wd = np.stack([np.sqrt(np.clip(1 - c * c, 0, None)), c, np.zeros_like(c)], axis=-1)
    f = _eval(L, 0, env, marg, cond, Wd)[:, 0]
    total = 2 * math.pi * np.trapezoid(f, x)
    assert total == pytest.approx(2.0, rel=1e-5)


def test_envmap_orientation_and_chi2():
    """Reference: Mitsuba's lat-long map rotated so local y is world +z: (sin phi sin theta, cos phi sin theta,
    cos theta) <-> (u, v) = (phi / 2 pi, theta / pi); chi-square in the (u, v) parameterisation with bins
    aligned to pixels (the density is constant per pixel: dw = 2 pi^2 sin theta du dv)."""
    rng = np.random.default_rng(0)
    H, Wd = 8, 16
    img = rng.uniform(0.0, 1.0, (H, Wd, 3)).astype(np.float32)
    img[2, 5] = 40.0
    img[7, :] = 0.0
    L, env, marg, cond = _setup([Lt.pack_light("envmap", [1.0, 1.0, 1.0])], img)
    # orientation: the centre of pixel (i, j)
    for i, j in ((0, 0), (2, 5), (6, 11)):
        th = (i + 0.5) / H * math.pi
        ph = (j + 0.5) / Wd * 2 * math.pi
        w = np.array([[math.sin(ph) * math.sin(th), math.cos(ph) * math.sin(th), math.cos(th)]])
        np.testing.assert_allclose(_eval(L, 0, env, marg, cond, w)[0], img[i, j], rtol=1e-6)
    # contract rtol 1e-6: light_pdf takes sin theta = sqrt(1 - z^2), which loses ~1e-16 / theta^2 of relative
    # precision next to the zenith (9e-9 at theta = 2e-5 among these samples); the sampler uses sin(theta)
    res = check_light(L, 0, env, marg, cond, angles="latlong", n=200_000, seed=9, res=(2 * Wd, 2 * H), sub=4,
                      rtol=1e-6)
    assert res.passed, res.message
    Wdirs, _, _ = light_draw(L, 0, env, marg, cond, 200_000, 9)
    assert np.all(np.arccos(np.clip(Wdirs[:, 2], -1, 1)) < 7 / 8 * math.pi)  # the black bottom row is never sampled


def test_directional_is_a_delta_light():
    """Convention: 'direction' is where light travels; sampling returns -direction and the irradiance."""
    L, env, marg, cond = _setup([Lt.pack_light("directional", [3.0, 2.0, 1.0], [0.0, 0.6, -0.8])])
    w, r, g, b, pdf, delta = Lt.light_sample(L, 0, env, marg, cond, 0.3, 0.7)
    assert delta and (r, g, b) == (3.0, 2.0, 1.0)
    np.testing.assert_allclose(w, [0.0, -0.6, 0.8])
    assert Lt.light_pdf(L, 0, env, marg, cond, w) == 0.0
    assert Lt.light_eval(L, 0, env, marg, cond, w) == (0.0, 0.0, 0.0)


def test_pack_lights_from_scene(tmp_path):
    """The packer reads Scene.lights dicts (and an EXR envmap) into the documented layout."""
    from pipeline.images import write_exr
    from pipeline.render_setup import pack_lights

    write_exr(tmp_path / "env.exr", np.full((4, 8, 3), 0.25, np.float32))
    ls = pack_lights([
        {"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": [1.0, 1.0, 1.0]},
        {"type": "constant", "radiance": [0.1, 0.2, 0.3]},
        {"type": "sg", "axis": [0.0, 0.0, 1.0], "sharpness": 5.0, "power": [2.0, 2.0, 2.0]},
        {"type": "envmap", "path": str(tmp_path / "env.exr"), "scale": 2.0},
    ])
    assert ls.lights.shape == (4, Lt.LIGHT_SIZE)
    np.testing.assert_allclose(ls.lights[:, 0], [0, 1, 2, 3])
    np.testing.assert_allclose(ls.lights[0, 4:7], [0, 0, 1])
    assert ls.lights[2, 8] == pytest.approx(5.0 / (2 * math.pi * (1 - math.exp(-10.0))))
    assert ls.env.shape == (4, 8, 3)
    w = np.array([[0.0, 0.0, 1.0]])
    assert _eval(ls.lights, 3, ls.env, ls.marginal, ls.conditional, w)[0, 0] == pytest.approx(0.5)


def test_harness_rejects_a_wrong_density():
    """The harness must fail: SG samples of sharpness 10 tested against the density of sharpness 11."""
    axis = np.array([0.0, 0.0, 1.0])
    L, env, marg, cond = _setup([Lt.pack_light("sg", [1.0] * 3, axis, 10.0)])
    L2 = L.copy()
    L2[0, 7] = 11.0
    L2[0, 8] = 1.0 / Lt.sg_normaliser(11.0)
    W, _, _ = light_draw(L, 0, env, marg, cond, 200_000, 1)
    res = chi2_test(directions_to_xy(W, axis), lambda x, y: _pdf(L2, 0, env, marg, cond, xy_to_directions(x, y, axis)),
                    SPHERE, res=(100, 40))
    assert not res.passed


def test_light_adapter_rejects_a_wrong_normalisation():
    """The adapter must fail: an SG row whose stored 1 / M(lambda) is 2 % too large (pdf and radiance
    consistent with each other, but the density integrates to 1.02)."""
    L, env, marg, cond = _setup([Lt.pack_light("sg", [1.0] * 3, [0.0, 0.0, 1.0], 10.0)])
    L[0, 8] *= 1.02
    res = check_light(L, 0, env, marg, cond, n=200_000, seed=1)
    assert not res.passed and "integrates" in res.message, res.message
