"""Material rows (stages/core/shading/material.py): material_sample / material_eval_pdf over packed rows
through the shading adapter (tests/chisquare.py: check_shading_model), and their delegation to the models.

The row interface takes a per-vertex context and both the tangent t and the normal n; the wrappers below
give it the shading interface with p = the row and frame = [t; n] (2, 3)."""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.shading import bcsdf as B
from stages.core.shading.lambert import lambert_eval, lambert_pdf
from stages.core.shading.material import (
    CTX_SIZE,
    material_eval_pdf,
    material_is_curve,
    material_prepare,
    material_sample,
    pack_material_bcsdf,
    pack_material_lambert,
)
from tests.chisquare import check_shading_model


@njit
def mat_sample(p, frame, wi, u0, u1, u2):
    ctx = np.empty(CTX_SIZE)
    material_prepare(p, frame[0], frame[1], wi, ctx)
    wo = np.zeros(3)
    r, g, b, pdf = material_sample(p, ctx, frame[0], frame[1], wi, u0, u1, u2, wo)
    return wo, r, g, b, pdf


@njit
def mat_pdf(p, frame, wi, wo):
    ctx = np.empty(CTX_SIZE)
    material_prepare(p, frame[0], frame[1], wi, ctx)
    return material_eval_pdf(p, ctx, frame[0], frame[1], wi, wo)[3]


@njit
def mat_eval(p, frame, wi, wo):
    ctx = np.empty(CTX_SIZE)
    material_prepare(p, frame[0], frame[1], wi, ctx)
    r, g, b, pdf = material_eval_pdf(p, ctx, frame[0], frame[1], wi, wo)
    return r, g, b


T = np.array([0.0, 0.6, 0.8])
N = np.array([0.0, 0.8, -0.6])     # outward normal of the hit, perpendicular to T
FRAME = np.stack([T, N])
WI = np.array([0.36, 0.48, -0.8])


def _rows():
    from pipeline.bcsdf_presets import load_bcsdf_preset

    return {"bcsdf-silk": pack_material_bcsdf(load_bcsdf_preset("silk")),
            "lambert": pack_material_lambert([0.2, 0.5, 0.9])}


@pytest.mark.parametrize("name", ["bcsdf-silk", "lambert"])
def test_material_sampling_chi2(name):
    """Reference: the shading adapter on material rows (one per model: the models themselves are tested in
    their own files): weight == f cos / pdf and pdf(sample) == pdf (first 2000 samples), chi-square of 200k
    samples against material_eval_pdf's pdf; BCSDF rows in (theta, phi) about the tangent (narrow R lobes),
    Lambert rows in (cos theta, phi) about the normal; Šidák over 2."""
    row = _rows()[name]
    curve = material_is_curve(row)
    assert curve == name.startswith("bcsdf")
    res = check_shading_model(mat_sample, mat_pdf, mat_eval, row, FRAME, WI, axis=T if curve else N,
                              angles="theta" if curve else "cos", n=200_000, seed=23,
                              res=(180, 48) if curve else (40, 40), sub=8 if curve else 6, n_tests=2, rtol=1e-9)
    assert res.passed, res.message


def test_rows_delegate_to_their_models():
    """Reference: the models themselves: a BCSDF row answers bcsdf_eval / bcsdf_pdf of its parameters at the
    tangent, a Lambert row lambert_eval / lambert_pdf of its albedo at the normal (the tangent is unused)."""
    rows = _rows()
    rng = np.random.default_rng(5)
    for _ in range(100):
        wo = rng.normal(size=3)
        wo /= np.linalg.norm(wo)
        p = rows["bcsdf-silk"][1:11]
        np.testing.assert_allclose(mat_eval(rows["bcsdf-silk"], FRAME, WI, wo), B.bcsdf_eval(p, T, WI, wo),
                                   rtol=1e-10, atol=1e-300)
        assert mat_pdf(rows["bcsdf-silk"], FRAME, WI, wo) == pytest.approx(B.bcsdf_pdf(p, T, WI, wo), rel=1e-10)
        alb = np.array([0.2, 0.5, 0.9])
        np.testing.assert_allclose(mat_eval(rows["lambert"], FRAME, WI, wo), lambert_eval(alb, N, WI, wo), rtol=1e-14)
        assert mat_pdf(rows["lambert"], FRAME, WI, wo) == pytest.approx(lambert_pdf(alb, N, WI, wo), rel=1e-14)
        assert mat_pdf(rows["lambert"], FRAME, WI, wo) == pytest.approx(max(0.0, float(N @ wo)) / math.pi, rel=1e-14)
