"""Distant lights (stages/render/lights.py): chi-square of every sampler, closed-form normalisations,
Mitsuba's lat-long orientation, the scene packer; the Lambertian fibre sampler; the harness itself."""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.rng import uniform
from stages.render import lights as Lt
from stages.core.shading.lambert import lambert_eval, lambert_pdf, lambert_sample
from tests.chisquare import chi2_test, directions_to_xy, xy_to_directions


@njit
def _sample(lights, k, env, marg, cond, n, seed):
    out = np.empty((n, 3))
    vals = np.empty((n, 4))
    for i in range(n):
        w, r, g, b, pdf, delta = Lt.light_sample(lights, k, env, marg, cond, uniform(seed, i, 0), uniform(seed, i, 1))
        out[i] = w
        vals[i, 0] = r
        vals[i, 1] = g
        vals[i, 2] = b
        vals[i, 3] = pdf
    return out, vals


@njit
def _pdf(lights, k, env, marg, cond, W):
    out = np.empty(W.shape[0])
    for i in range(W.shape[0]):
        out[i] = Lt.light_pdf(lights, k, env, marg, cond, W[i])
    return out


@njit
def _eval(lights, k, env, marg, cond, W):
    out = np.empty((W.shape[0], 3))
    for i in range(W.shape[0]):
        r, g, b = Lt.light_eval(lights, k, env, marg, cond, W[i])
        out[i, 0] = r
        out[i, 1] = g
        out[i, 2] = b
    return out


def _setup(rows, img=None):
    env, marg, cond = Lt.envmap_tables(img)
    return np.asarray(rows), env, marg, cond


SPHERE = ((-1.0, 1.0), (-math.pi, math.pi))


@pytest.mark.parametrize("kind,sharpness", [("constant", 0.0), ("sg", 0.5), ("sg", 10.0), ("sg", 80.0)])
def test_sampling_chi2_sphere(kind, sharpness):
    """Reference: chi-square of 200k samples against light_pdf integrated over (cos theta, phi) bins
    about the lobe axis; the sampled value equals light_eval and the pdf light_pdf."""
    axis = np.array([0.3, -0.5, 0.8])
    L, env, marg, cond = _setup([Lt.pack_light(kind, [1.0, 2.0, 3.0], axis, sharpness)])
    W, vals = _sample(L, 0, env, marg, cond, 200_000, 5)
    res = chi2_test(directions_to_xy(W, axis), lambda x, y: _pdf(L, 0, env, marg, cond, xy_to_directions(x, y, axis)),
                    SPHERE, res=(100, 40), alpha=0.01, n_tests=5)
    assert res.passed, res.message
    np.testing.assert_allclose(vals[:2000, :3], _eval(L, 0, env, marg, cond, W[:2000]), rtol=1e-12)
    np.testing.assert_allclose(vals[:2000, 3], _pdf(L, 0, env, marg, cond, W[:2000]), rtol=1e-12)


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
    Wdirs, vals = _sample(L, 0, env, marg, cond, 200_000, 9)
    th = np.arccos(np.clip(Wdirs[:, 2], -1, 1))
    ph = np.mod(np.arctan2(Wdirs[:, 0], Wdirs[:, 1]), 2 * math.pi)
    uv = np.stack([ph / (2 * math.pi), th / math.pi], -1)

    def pdf_uv(u, v):
        t = v * math.pi
        p = u * 2 * math.pi
        dirs = np.stack([np.sin(p) * np.sin(t), np.cos(p) * np.sin(t), np.cos(t)], -1)
        return _pdf(L, 0, env, marg, cond, dirs) * 2 * math.pi ** 2 * np.sin(t)

    res = chi2_test(uv, pdf_uv, ((0.0, 1.0), (0.0, 1.0)), res=(2 * Wd, 2 * H), sub=4)
    assert res.passed, res.message
    assert np.all(th < 7 / 8 * math.pi)  # the black bottom row is never sampled


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


@njit
def _lambert_samples(n_, alb, n, seed):
    out = np.empty((n, 3))
    wts = np.empty((n, 3))
    for i in range(n):
        w, a, b, c, pdf = lambert_sample(alb, n_, n_, 0.0, uniform(seed, i, 0), uniform(seed, i, 1))
        out[i] = w
        f0, f1, f2 = lambert_eval(alb, n_, n_, w)
        wts[i, 0] = f0 / pdf - a
        wts[i, 1] = lambert_pdf(alb, n_, n_, w) - pdf
        wts[i, 2] = 0.0
    return out, wts


def test_lambert_fibre_sampling_chi2():
    """Reference: chi-square of cosine-weighted samples about the surface normal; weight = albedo exactly."""
    nrm = np.array([0.6, 0.0, -0.8])
    alb = np.array([0.2, 0.5, 0.9])
    W, chk = _lambert_samples(nrm, alb, 200_000, 3)
    res = chi2_test(directions_to_xy(W, nrm), lambda x, y: np.where(x > 0, x / math.pi, 0.0), SPHERE, res=(40, 40))
    assert res.passed, res.message
    assert np.abs(chk).max() < 1e-12


def test_harness_rejects_a_wrong_density():
    """The harness must fail: SG samples of sharpness 10 tested against the density of sharpness 11."""
    axis = np.array([0.0, 0.0, 1.0])
    L, env, marg, cond = _setup([Lt.pack_light("sg", [1.0] * 3, axis, 10.0)])
    L2 = L.copy()
    L2[0, 7] = 11.0
    L2[0, 8] = 1.0 / Lt.sg_normaliser(11.0)
    W, _ = _sample(L, 0, env, marg, cond, 200_000, 1)
    res = chi2_test(directions_to_xy(W, axis), lambda x, y: _pdf(L2, 0, env, marg, cond, xy_to_directions(x, y, axis)),
                    SPHERE, res=(100, 40))
    assert not res.passed
