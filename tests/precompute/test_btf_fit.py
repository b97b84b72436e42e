"""The seed 002 fit (stages.precompute.btf_fit; Daubert et al. 2001 §5, §5.1) and the texel model it fits
(stages.core.btf, Eq. 1-2).

References:
- the closed form of Eq. 2 written out in numpy (independent of the kernels), for ``lafortune_lobe``,
  ``texel_f1`` and ``predict_samples``;
- round trips: samples made by the model itself are reproduced by the fit (1 and 2 lobes, T = 1 and a
  non-trivial T(v)); parameters are compared where they are identifiable;
- ``numpy.linalg.lstsq`` of r = T f, for Eq. 4;
- the exact least-squares identity behind §5.1 (the alpha-weighted error of the concatenated
  samples equals the group mean's error plus a constant), and brute-force group means;
- a mip level of a spatially uniform texture, which must equal level 0;
- byte equality at 1 and 2 threads, and texel by texel against all at once;
- degenerate inputs, checked to be finite, with the documented fallbacks and the bound of the
  documented initial guess.
"""
import numba
import numpy as np
import pytest

from stages.core.btf import hemisphere_grid, lafortune_lobe, texel_f1
from stages.precompute.btf_fit import (
    ANISO,
    N_MAX,
    N_MIN,
    N_START,
    PEAK_MAX,
    BtfFit,
    fit_btf,
    fit_levels,
    group_level,
    predict_samples,
    table_entry,
)

VIEWS = hemisphere_grid(4, 6)
LIGHTS = hemisphere_grid(4, 6)


def _frames(rng, n, tilt=0.3):
    """n random orthonormal (normal, tangent) pairs near +z."""
    nrm = rng.normal(size=(n, 3)) * tilt
    nrm[:, 2] = 1.0
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    t = np.cross(nrm, rng.normal(size=(n, 3)))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return np.stack([nrm, t], axis=1)


def _f1_numpy(rho, lobes, frame, l, v):
    """Eq. 2 closed form: (..., 3) for light l and view v (pattern space), lobes (K, 3, 4)."""
    n, t = frame[0], frame[1]
    b = np.cross(n, t)
    lp = np.array([l @ t, l @ b, l @ n])
    vp = np.array([v @ t, v @ b, v @ n])
    if l[2] <= 0.0:
        return np.zeros(3)
    out = np.array(rho, dtype=float).copy()
    for k in range(lobes.shape[0]):
        a = (lobes[k, :, :3] * (lp * vp)[None, :]).sum(axis=1)
        out += np.where(a > 0.0, np.abs(a) ** lobes[k, :, 3], 0.0)
    return l[2] * out


def _random_model(rng, n, K, table=False):
    rho = rng.uniform(0.05, 0.3, (n, 3))
    lob = np.zeros((n, K, 3, 4))
    lob[:, 0, :, 0] = -rng.uniform(0.8, 1.0, (n, 3))
    lob[:, 0, :, 1] = -rng.uniform(0.8, 1.0, (n, 3))
    lob[:, 0, :, 2] = rng.uniform(0.8, 1.0, (n, 3))
    lob[:, 0, :, 3] = rng.uniform(4.0, 15.0, (n, 3))
    if K == 2:                                       # a broad retro-reflective lobe
        lob[:, 1, :, :3] = rng.uniform(0.5, 0.8, (n, 3, 3))
        lob[:, 1, :, 3] = rng.uniform(1.0, 3.0, (n, 3))
    tab = np.ones((n, len(VIEWS), 4))
    if table:                                        # darker and redder towards grazing views
        tab[..., :3] = 1.0 - (1.0 - VIEWS[None, :, 2:3]) * rng.uniform(0.2, 0.5, (n, 1, 3))
    return rho, lob, tab


# ------------------------------------------------------------------------------------------------
# 1. the model against its closed form
def test_lobe_and_f1_match_the_closed_form():
    """Closed form of Eq. 2 (numpy): random directions (lights below the plane included) and random
    signed parameters, so many lobes have a <= 0 and must give 0 (footnote 3)."""
    rng = np.random.default_rng(1)
    n_neg = 0
    for _ in range(200):
        l = rng.normal(size=3)
        v = rng.normal(size=3)
        v[2] = abs(v[2])
        l /= np.linalg.norm(l)
        v /= np.linalg.norm(v)
        frame = _frames(rng, 1, tilt=0.6)[0]
        rho = rng.uniform(0, 1, 3)
        lobes = np.concatenate([rng.normal(size=(2, 3, 3)), rng.uniform(0.2, 20, (2, 3, 1))], axis=2)
        ref = _f1_numpy(rho, lobes, frame, l, v)
        for c in range(3):
            assert texel_f1(rho, lobes, frame, c, *l, *v) == pytest.approx(ref[c], rel=1e-12, abs=1e-15)
        cx, cy, cz, nn = lobes[0, 0]
        a = cx * l[0] * v[0] + cy * l[1] * v[1] + cz * l[2] * v[2]
        got = lafortune_lobe(cx, cy, cz, nn, *l, *v)
        if a <= 0:
            n_neg += 1
            assert got == 0.0
        else:
            assert got == pytest.approx(a ** nn, rel=1e-12)
    assert n_neg > 50


def test_predict_samples_is_table_times_f1():
    """Closed form: predict_samples(...)[t, v, l, c] = T(v)_c f_1(l, v)_c (Eq. 1) for every entry."""
    rng = np.random.default_rng(2)
    rho, lob, tab = _random_model(rng, 3, 2, table=True)
    lob[:, 1, :, :3] *= rng.choice([-1.0, 1.0], size=(3, 3, 3))
    fr = _frames(rng, 3)
    lights = np.concatenate([LIGHTS, [[0.6, 0.0, -0.8]]])       # one below the fabric plane: 0
    pred = predict_samples(rho, lob, tab, fr, VIEWS, lights)
    for t in range(3):
        for v in range(len(VIEWS)):
            for li in range(len(lights)):
                ref = tab[t, v, :3] * _f1_numpy(rho[t], lob[t], fr[t], lights[li], VIEWS[v])
                np.testing.assert_allclose(pred[t, v, li], ref, rtol=1e-12, atol=1e-15)
    assert np.all(pred[:, :, -1] == 0.0)


# ------------------------------------------------------------------------------------------------
# 2. round trips
@pytest.mark.parametrize("K", [1, 2])
def test_fit_recovers_its_own_model_with_a_white_table(K):
    """Round trip: noiseless samples of random models (T = 1, tilted frames, a hole view) are reproduced
    to 1e-6 relative. With one lobe, rho and the lobe are identifiable and compared directly. With two
    they are compared up to the order of the lobes."""
    rng = np.random.default_rng(10 + K)
    n = 3
    rho, lob, tab = _random_model(rng, n, K)
    fr = _frames(rng, n)
    alpha = np.ones((n, len(VIEWS)))
    alpha[:, 5] = 0.0
    tab[:, 5, :3] = 0.0
    smp = predict_samples(rho, lob, tab, fr, VIEWS, LIGHTS)
    smp[:, 5] = 7.0                                  # a hole's samples must not matter
    fit = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=K, threshold=1e-9, max_rounds=20, max_iter=300)
    assert isinstance(fit, BtfFit)
    pred = predict_samples(fit.rho, fit.lobes, fit.table, fr, VIEWS, LIGHTS)
    ok = alpha > 0
    scale = np.abs(smp[ok]).max()
    assert np.abs(pred[ok] - smp[ok]).max() < 1e-6 * scale
    assert np.all(fit.table[:, 5, :3] == 0.0) and np.all(fit.table[:, :, 3] == alpha)
    assert np.all(fit.rmse < 1e-6 * scale) and np.all(fit.rmse_no_table < 1e-6 * scale)
    assert fit.converged.all()
    np.testing.assert_allclose(fit.table[:, ok[0], :3], 1.0, atol=1e-6)
    np.testing.assert_allclose(fit.rho, rho, rtol=1e-5, atol=1e-7)
    got = fit.lobes
    if K == 2:       # order the lobes by exponent (the true ones: sharp mirror lobe first, N >= 4 > 3)
        order = np.argsort(-got[..., 3], axis=1)
        got = np.take_along_axis(got, order[..., None], axis=1)
    np.testing.assert_allclose(got, lob, rtol=1e-4)


@pytest.mark.parametrize("K", [1, 2])
def test_fit_reproduces_samples_with_a_view_dependent_table(K):
    """Round trip with a non-trivial T(v): T f_1 is only determined up to a common factor, so the
    predictions are compared, to 1e-6 relative. The table must beat the lobes alone, which cannot
    make the colour shift with the view."""
    rng = np.random.default_rng(20 + K)
    n = 2
    rho, lob, tab = _random_model(rng, n, K, table=True)
    fr = _frames(rng, n)
    alpha = np.ones((n, len(VIEWS)))
    smp = predict_samples(rho, lob, tab, fr, VIEWS, LIGHTS)
    fit = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=K, threshold=1e-9, max_rounds=400, max_iter=200)
    pred = predict_samples(fit.rho, fit.lobes, fit.table, fr, VIEWS, LIGHTS)
    scale = np.abs(smp).max()
    assert np.abs(pred - smp).max() < 1e-6 * scale
    assert np.all(fit.rmse < 1e-6 * scale)
    assert np.all(fit.rmse_no_table > 1e3 * fit.rmse)
    assert np.all(fit.rounds > 1)


# ------------------------------------------------------------------------------------------------
# 3. Eq. 4
def test_table_entry_is_the_least_squares_optimum():
    """numpy.linalg.lstsq of r = T f (one unknown) for random f and r; 0 when f = 0."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        m = int(rng.integers(1, 40))
        f = rng.normal(size=m) * rng.uniform(0.01, 100)
        r = rng.normal(size=m) + rng.uniform(-2, 2) * f
        ref = np.linalg.lstsq(f[:, None], r, rcond=None)[0][0]
        assert table_entry(f, r) == pytest.approx(ref, rel=1e-12, abs=1e-14)
    assert table_entry(np.zeros(5), np.ones(5)) == 0.0


def test_fitted_table_is_eq4_of_the_fitted_lobes():
    """numpy.linalg.lstsq, per view and channel, of the samples against f_1 of the returned rho and lobes
    (closed form): the returned T(v) is Eq. 4's optimum for the returned lobes, on noisy data."""
    rng = np.random.default_rng(4)
    rho, lob, tab = _random_model(rng, 2, 2, table=True)
    fr = _frames(rng, 2)
    smp = (predict_samples(rho, lob, tab, fr, VIEWS, LIGHTS)
           * (1 + 0.05 * rng.normal(size=(2, len(VIEWS), len(LIGHTS), 3))))
    alpha = np.ones((2, len(VIEWS)))
    fit = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=2)
    for t in range(2):
        for v in range(len(VIEWS)):
            f = np.array([_f1_numpy(fit.rho[t], fit.lobes[t], fr[t], l, VIEWS[v]) for l in LIGHTS])
            for c in range(3):
                ref = np.linalg.lstsq(f[:, c:c + 1], smp[t, v, :, c], rcond=None)[0][0]
                assert fit.table[t, v, c] == pytest.approx(ref, rel=1e-9, abs=1e-12)


# ------------------------------------------------------------------------------------------------
# 4. mip levels
def test_group_level_is_the_weighted_mean_and_equals_the_concatenated_fit():
    """Brute force group means (alpha-weighted, plain mean where a group is all holes); the exact
    identity sum_t alpha_t (r_t - m)^2 = W (rbar - m)^2 + const for any model value m; mean frames
    orthonormal, the normal the normalised mean of the normals."""
    rng = np.random.default_rng(5)
    res, V, L = 4, 3, 2
    smp = rng.uniform(0, 1, (res, res, V, L, 3))
    alpha = rng.uniform(0, 1, (res, res, V))
    alpha[alpha < 0.3] = 0.0
    alpha[0:2, 0:2, 1] = 0.0                         # group (0, 0) is a hole at view 1
    fr = _frames(rng, res * res).reshape(res, res, 2, 3)
    g = group_level(smp, alpha, fr, res, 1)
    assert g.res == 2 and g.samples.shape == (4, V, L, 3) and g.alpha.shape == (4, V) and g.frames.shape == (4, 2, 3)
    for i in range(2):
        for j in range(2):
            blk = smp[2 * i:2 * i + 2, 2 * j:2 * j + 2].reshape(4, V, L, 3)
            a = alpha[2 * i:2 * i + 2, 2 * j:2 * j + 2].reshape(4, V)
            W = a.sum(axis=0)
            for v in range(V):
                ref = (a[:, v, None, None] * blk[:, v]).sum(0) / W[v] if W[v] > 0 else blk[:, v].mean(0)
                np.testing.assert_allclose(g.samples[2 * i + j, v], ref, rtol=1e-12)
                if W[v] > 0:
                    m1, m2 = rng.normal(size=(2, L, 3))
                    e_cat = [(a[:, v, None, None] * (blk[:, v] - m) ** 2).sum(0) for m in (m1, m2)]
                    e_mean = [W[v] * (g.samples[2 * i + j, v] - m) ** 2 for m in (m1, m2)]
                    np.testing.assert_allclose(e_cat[0] - e_cat[1], e_mean[0] - e_mean[1], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(g.alpha[2 * i + j], W / 4, rtol=1e-12)
            nm = fr[2 * i:2 * i + 2, 2 * j:2 * j + 2, 0].reshape(4, 3).mean(0)
            np.testing.assert_allclose(g.frames[2 * i + j, 0], nm / np.linalg.norm(nm), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(g.frames, axis=2), 1.0, rtol=1e-12)
    np.testing.assert_allclose((g.frames[:, 0] * g.frames[:, 1]).sum(1), 0.0, atol=1e-12)
    top = group_level(smp, alpha, fr, res, 2)
    assert top.res == 1 and top.samples.shape == (1, V, L, 3)
    with pytest.raises(ValueError):
        group_level(smp, alpha, fr, res, 3)


def test_mip_levels_of_a_uniform_texture_equal_level_0():
    """A spatially uniform texture (every texel the same samples, alpha and frame): every mip level's
    fit equals the level-0 fit (rho, lobes, table, rmse), and there are log2(res) + 1 levels."""
    rng = np.random.default_rng(6)
    rho, lob, tab = _random_model(rng, 1, 1, table=True)
    fr = _frames(rng, 1)
    one = (predict_samples(rho, lob, tab, fr, VIEWS, LIGHTS)[0]
           * (1 + 0.03 * rng.normal(size=(len(VIEWS), len(LIGHTS), 3))))
    res = 4
    smp = np.broadcast_to(one, (res, res) + one.shape).copy()
    alpha = np.ones((res, res, len(VIEWS)))
    alpha[..., 7] = 0.0
    alpha[..., 8] = 0.5
    frames = np.broadcast_to(fr[0], (res, res, 2, 3)).copy()
    out = fit_levels(smp, alpha, frames, VIEWS, LIGHTS, lobes=1, threshold=0.01, max_rounds=20, max_iter=100)
    assert len(out) == 3 and [len(f.rho) for f in out] == [16, 4, 1]
    base = out[0]
    for fit in out:
        for name in ("rho", "lobes", "table", "rmse", "rmse_no_table", "frames"):
            a, b = getattr(fit, name), getattr(base, name)[: len(getattr(fit, name))]
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9, err_msg=name)
        for name in ("rmse", "rmse_no_table", "mean_radiance"):
            np.testing.assert_allclose(getattr(fit.summary, name), getattr(base.summary, name), rtol=1e-6)
        assert np.all(fit.summary.rmse < fit.summary.rmse_no_table)
    # the pooled summary of one texel is its own rmse; the mean radiance is the alpha-weighted one
    np.testing.assert_allclose(out[2].summary.rmse, out[2].rmse[0], rtol=1e-12)
    ref = (alpha[0, 0, :, None, None] * one).sum((0, 1)) / (alpha[0, 0].sum() * len(LIGHTS))
    np.testing.assert_allclose(out[2].summary.mean_radiance, ref, rtol=1e-9)


# ------------------------------------------------------------------------------------------------
# 5. determinism
def test_same_bytes_at_one_and_two_threads_and_texel_by_texel():
    """Contract: each texel is fitted on its own, sequentially, so 1 thread, 2 threads and one texel at a
    time give identical bytes."""
    rng = np.random.default_rng(7)
    n = 6
    rho, lob, tab = _random_model(rng, n, 2, table=True)
    fr = _frames(rng, n)
    smp = (predict_samples(rho, lob, tab, fr, VIEWS, LIGHTS)
           * (1 + 0.05 * rng.normal(size=(n, len(VIEWS), len(LIGHTS), 3))))
    alpha = np.where(rng.uniform(size=(n, len(VIEWS))) < 0.2, 0.0, 1.0)
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=2)
        numba.set_num_threads(max(2, n0) if numba.config.NUMBA_NUM_THREADS >= 2 else 1)
        two = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=2)
    finally:
        numba.set_num_threads(n0)
    singles = [fit_btf(smp[t:t + 1], alpha[t:t + 1], VIEWS, LIGHTS, fr[t:t + 1], lobes=2) for t in range(n)]
    for name in BtfFit._fields:
        if name == "summary":
            for x, y in zip(one.summary, two.summary):
                assert np.asarray(x).tobytes() == np.asarray(y).tobytes()
            continue
        a = getattr(one, name)
        assert a.tobytes() == getattr(two, name).tobytes(), name
        assert a.tobytes() == np.concatenate([getattr(s, name) for s in singles]).tobytes(), name


# ------------------------------------------------------------------------------------------------
# 6. degenerate inputs
def _all_finite(fit):
    return all(np.all(np.isfinite(getattr(fit, f))) for f in ("rho", "lobes", "table", "rmse", "rmse_no_table"))


def test_degenerate_inputs_stay_finite():
    """No NaN or inf from: all-zero samples (the exact fit rho = C = 0, T = 0), a single nonzero sample,
    a texel that is all holes (no views: T = 0, zero rounds), huge (2^60 ~ 1e18) and tiny (2^-60) values.
    The fit runs in units of each channel's largest sample, so 2^60 x data gives 2^60 x the same
    predictions."""
    BIG = 2.0 ** 60
    rng = np.random.default_rng(8)
    n, V, L = 5, len(VIEWS), len(LIGHTS)
    rho, lob, tab = _random_model(rng, 1, 2)
    fr = _frames(rng, n)
    base = predict_samples(np.repeat(rho, n, 0), np.repeat(lob, n, 0), np.repeat(tab, n, 0), fr, VIEWS, LIGHTS)
    base *= 1 + 0.05 * rng.normal(size=base.shape)
    smp = np.zeros((n, V, L, 3))
    smp[1, 3, 17, 1] = 2.5                           # a single nonzero sample
    smp[3] = base[3] * BIG
    smp[4] = base[3] / BIG
    fr[4] = fr[3]
    alpha = np.ones((n, V))
    alpha[2] = 0.0                                   # texel 2: holes only
    smp[2] = base[2]
    fit = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=2)
    assert _all_finite(fit)
    assert np.all(fit.rho[0] == 0) and np.all(fit.lobes[0, :, :, :3] == 0) and np.all(fit.table[0, :, :3] == 0)
    assert np.all(fit.rmse[0] == 0) and fit.converged[0]
    assert np.all(fit.table[2, :, :3] == 0) and fit.rounds[2] == 0 and np.all(fit.rmse[2] == 0)
    assert fit.rmse[1, 1] < 2.5 / np.sqrt(V * L) and np.all(fit.rmse[1, [0, 2]] == 0)
    pred = predict_samples(fit.rho, fit.lobes, fit.table, fr, VIEWS, LIGHTS)
    assert np.all(np.isfinite(pred))
    np.testing.assert_allclose(pred[3] / BIG, pred[4] * BIG, rtol=1e-9)
    np.testing.assert_allclose(fit.rmse[3] / BIG, fit.rmse[4] * BIG, rtol=1e-9)
    f32 = fit_btf(smp[3:4].astype(np.float32), alpha[3:4], VIEWS, LIGHTS, fr[3:4], lobes=2)
    assert _all_finite(f32)
    with pytest.raises(ValueError):
        fit_btf(np.full((1, V, L, 3), np.nan), alpha[:1], VIEWS, LIGHTS, fr[:1])
    with pytest.raises(ValueError):
        fit_btf(np.full((1, V, L, 3), 1e21), alpha[:1], VIEWS, LIGHTS, fr[:1])
    with pytest.raises(ValueError):
        fit_btf(smp[:1], alpha[:1], VIEWS, LIGHTS, fr[:1], lobes=3)


def test_non_convergence_is_flagged_and_keeps_the_best_iterate():
    """One LM iteration cannot fit noisy two-lobe data: ``converged`` is False, and the returned model
    has an error no larger than the documented initial guess (rho_d / 2; mirror lobes (-1.22 c, -c, c)
    and (-c, -1.22 c, c) with c = (rho_d / 4)^(1/N_START); T = 1), evaluated here in closed form. The
    returned rmse is the returned model's (recomputed by predict_samples)."""
    rng = np.random.default_rng(9)
    n = 3
    rho, lob, tab = _random_model(rng, n, 2, table=True)
    fr = _frames(rng, n)
    smp = (predict_samples(rho, lob, tab, fr, VIEWS, LIGHTS)
           * (1 + 0.05 * rng.normal(size=(n, len(VIEWS), len(LIGHTS), 3))))
    alpha = np.ones((n, len(VIEWS)))
    fit = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=2, max_rounds=1, max_iter=1)
    assert not fit.converged.any() and np.all(fit.rounds == 1)
    lz = LIGHTS[:, 2]
    rho_d = (smp * lz[None, None, :, None]).sum((1, 2)) / (len(VIEWS) * (lz ** 2).sum())
    c = (rho_d / 4.0) ** (1.0 / N_START)
    l0 = np.zeros((n, 2, 3, 4))
    l0[:, 0, :, 0], l0[:, 0, :, 1], l0[:, 0, :, 2] = -ANISO * c, -c, c
    l0[:, 1, :, 0], l0[:, 1, :, 1], l0[:, 1, :, 2] = -c, -ANISO * c, c
    l0[..., 3] = N_START
    start = predict_samples(rho_d / 2, l0, np.ones((n, len(VIEWS), 4)), fr, VIEWS, LIGHTS)
    rmse0 = np.sqrt(((start - smp) ** 2).mean((1, 2)))
    pred = predict_samples(fit.rho, fit.lobes, fit.table, fr, VIEWS, LIGHTS)
    rmse = np.sqrt(((pred - smp) ** 2).mean((1, 2)))
    np.testing.assert_allclose(fit.rmse, rmse, rtol=1e-9)
    assert np.all(fit.rmse <= rmse0 * (1 + 1e-12))
    assert np.all(fit.rmse_no_table <= rmse0 * (1 + 1e-12))
    full = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=2)
    assert np.all(full.rmse < fit.rmse)


def test_garbage_data_gives_a_bounded_model():
    """Constraints (module doc): on random garbage (uniform, signed normal, log-normal over 20 decades,
    isolated spikes; random frames tilted anywhere; fractional alpha with holes), every output is finite,
    rho >= 0, N in [N_MIN, N_MAX], each lobe's peak max|C|^N at most PEAK_MAX times the channel's largest
    sample, and the model is finite at random directions off the grid too."""
    V, L = len(VIEWS), len(LIGHTS)
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        n = 6
        nrm = rng.normal(size=(n, 3))
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        t = np.cross(nrm, rng.normal(size=(n, 3)))
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        fr = np.stack([nrm, t], axis=1)
        smp = [rng.uniform(0, 1, (n, V, L, 3)), rng.normal(size=(n, V, L, 3)),
               np.exp(rng.normal(size=(n, V, L, 3)) * 10).clip(0, 1e19), np.zeros((n, V, L, 3))][seed]
        if seed == 3:
            idx = rng.integers(0, V, (n, 2))
            smp[np.arange(n), idx[:, 0], idx[:, 1]] = rng.uniform(0, 1e19, (n, 3))
        alpha = rng.uniform(0, 1, (n, V)) * (rng.uniform(size=(n, V)) > 0.4)
        for K in (1, 2):
            fit = fit_btf(smp, alpha, VIEWS, LIGHTS, fr, lobes=K, max_rounds=3, max_iter=30)
            assert _all_finite(fit)
            assert np.all(fit.rho >= 0)
            N = fit.lobes[..., 3]
            assert np.all(N >= N_MIN) and np.all(N <= N_MAX)
            smax = np.abs(smp * (alpha > 0)[:, :, None, None]).max(axis=(1, 2))          # (n, 3)
            peak = np.abs(fit.lobes[..., :3]).max(axis=-1) ** N                          # (n, K, 3)
            assert np.all(peak <= PEAK_MAX * np.where(smax > 0, smax, 1.0)[:, None, :] * (1 + 1e-9))
            dirs = rng.normal(size=(40, 3))
            dirs[:, 2] = np.abs(dirs[:, 2])
            dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
            off = predict_samples(fit.rho, fit.lobes, np.ones((n, 40, 4)), fr, dirs, dirs)
            assert np.all(np.isfinite(off))
