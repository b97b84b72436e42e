"""Segment visibility functions (stages.precompute.svf, seed 001 §4.1) against their references:
visibility images against ``periodic_hit_outside`` per pixel (and closed-form hand cases), SSDFs against the
brute-force nearest opposite pixel over all pixel pairs, the PCA against numpy's SVD of the whole
SSDF matrix, SG weights against a brute-force nearest-axis assignment and the visible solid angle,
and bytes identical at 1 and 2 numba threads."""
import math

import numba
import numpy as np
import pytest
from numba import njit

import stages.core.svf as core_svf
from stages.core.sg import sg_mass, spherical_fibonacci_axes
from stages.precompute import svf
from stages.precompute.periodic import periodic_hit_outside, periodic_scene, ray_start

RES = 32


@njit(cache=True)
def _reference_images(psc, z_lo, z_hi, mids, capsules, fibres, R, C, max_dist, out):
    for s in range(mids.shape[0]):
        for r in range(R):
            for c in range(C):
                x, y, z = core_svf.pixel_direction(r, c, R, C)
                ox, oy, oz, t = ray_start(mids[s, 0], mids[s, 1], mids[s, 2], capsules[s], x, y, z)
                h = periodic_hit_outside(psc, z_lo, z_hi, ox, oy, oz, x, y, z, fibres[s], max_dist - t)
                out[s, r, c] = 1 if h.t == np.inf else 0


def _segments(art, k):
    return svf.exemplar_segments(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"],
                                 art["ex_period"], k)


@pytest.fixture(scope="module")
def tiny_svf(tiny_tiling):
    """Exemplar 0 (plain) of the tiny tiling: segments, periodic scene and its 32 x 32 packed images."""
    _, sc, art = tiny_tiling
    seg = _segments(art, 0)
    psc = periodic_scene(sc, 0)
    packed = svf.visibility_images(psc, 0, seg.z_lo, seg.z_hi, seg.mids, seg.fibre, RES, RES, capsules=seg.capsules)
    return seg, psc, packed


# ------------------------------------------------------------------------------------------------ segments
def test_exemplar_segments_follow_the_global_numbering(tiny_tiling):
    """Reference: the numbering of the tiling (fibre f's segment i is ex_offsets[f] - f + i, between
    points ex_offsets[f] + i and + i + 1), walked fibre by fibre; the slab from the points and radii."""
    _, _, art = tiny_tiling
    O, P, Rr = art["ex_offsets"], art["ex_points"], art["ex_radius"]
    for k in range(2):
        seg = _segments(art, k)
        ids, fib, mids = [], [], []
        for f in range(art["ex_fibers"][k], art["ex_fibers"][k + 1]):
            for i in range(O[f + 1] - O[f] - 1):
                ids.append(O[f] - f + i)
                fib.append(f)
                mids.append(0.5 * (P[O[f] + i] + P[O[f] + i + 1]))
        assert np.array_equal(seg.ids, ids) and np.array_equal(seg.fibre, fib)
        assert np.array_equal(seg.mids, np.array(mids))
        p = slice(O[art["ex_fibers"][k]], O[art["ex_fibers"][k + 1]])
        assert seg.z_lo == (P[p, 2] - Rr[p]).min() and seg.z_hi == (P[p, 2] + Rr[p]).max()


# ------------------------------------------------------------------------------------------------ 1. visibility
@pytest.mark.parametrize("from_surface", [True, False])
def test_visibility_images_match_periodic_hit_per_pixel(tiny_tiling, from_surface):
    """Reference: one ``periodic_hit_outside`` per pixel centre (visible iff it escapes) from where the ray
    starts (the segment's surface, ``periodic.ray_start``, or its midpoint), both exemplars, 32 x 24 pixels,
    every fourth segment: identical bits. Starting on the surface sees more (the midpoint's rays also
    meet the fibres that pass through the segment's own capsule)."""
    _, sc, art = tiny_tiling
    R, C = 32, 24
    for k in range(2):
        seg = _segments(art, k)
        psc = periodic_scene(sc, k)
        sel = np.arange(0, len(seg.ids), 4 if k == 0 else 25)
        caps = seg.capsules[sel] if from_surface else np.zeros((len(sel), 7))
        packed = svf.visibility_images(psc, k, seg.z_lo, seg.z_hi, seg.mids[sel], seg.fibre[sel], R, C, capsules=caps)
        ref = np.zeros((len(sel), R, C), np.uint8)
        _reference_images(psc, seg.z_lo, seg.z_hi, seg.mids[sel], caps, seg.fibre[sel], R, C,
                          svf.default_max_dist(psc, k), ref)
        assert np.array_equal(svf.unpack_images(packed, R, C), ref)
        assert np.array_equal(packed, svf.pack_images(ref))
        assert 0.02 < ref.mean() < 0.9        # neither trivially visible nor trivially occluded
        if from_surface:
            mid = svf.visibility_images(psc, k, seg.z_lo, seg.z_hi, seg.mids[sel], seg.fibre[sel], R, C)
            assert svf.unpack_images(mid, R, C).mean() < ref.mean()


def test_visibility_hand_cases(tiny_tiling):
    """Closed form: from the top of the slab (z = z_hi) every upward ray leaves the fabric at once, so
    the upper half of the rows is visible; from its bottom the lower half; from a segment's midpoint
    with its own fibre not skipped, its own capsule lets the rays through (it contains the midpoint) but
    the neighbouring segments of the chain are occluders: the image is a subset of the one that skips
    the fibre, and smaller over all."""
    _, sc, art = tiny_tiling
    seg = _segments(art, 0)
    psc = periodic_scene(sc, 0)
    R = C = 16
    W, H = seg.period
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 1, (5, 2)) * [W, H]
    top = svf.unpack_images(svf.visibility_images(psc, 0, seg.z_lo, seg.z_hi,
                                                  np.c_[xy, np.full(5, seg.z_hi)], np.full(5, -1), R, C), R, C)
    bottom = svf.unpack_images(svf.visibility_images(psc, 0, seg.z_lo, seg.z_hi,
                                                     np.c_[xy, np.full(5, seg.z_lo)], np.full(5, -1), R, C), R, C)
    assert top[:, :R // 2].all() and bottom[:, R // 2:].all()
    assert not top[:, R // 2:].all() and not bottom[:, :R // 2].all()   # the fabric is there
    sel = np.arange(0, len(seg.ids), 7)
    own = svf.visibility_images(psc, 0, seg.z_lo, seg.z_hi, seg.mids[sel], np.full(len(sel), -1), R, C)
    skip = svf.visibility_images(psc, 0, seg.z_lo, seg.z_hi, seg.mids[sel], seg.fibre[sel], R, C)
    own_img = svf.unpack_images(own, R, C)
    skip_img = svf.unpack_images(skip, R, C)
    assert skip.any() and not (own_img & ~skip_img).any()
    assert own_img.sum() < skip_img.sum()


def test_visibility_chunks_are_independent(tiny_svf):
    """Reference: the images of the whole exemplar; any contiguous chunk gives the same rows."""
    seg, psc, packed = tiny_svf
    a, b = 37, 101
    part = svf.visibility_images(psc, 0, seg.z_lo, seg.z_hi, seg.mids[a:b], seg.fibre[a:b], RES, RES,
                                 capsules=seg.capsules[a:b])
    assert np.array_equal(part, packed[a:b])


# ------------------------------------------------------------------------------------------------ 2. SSDF
def _brute_ssdf(img):
    """All pixel pairs: the angle 2 asin(|p - q| / 2) between centres, nearest of the opposite value."""
    R, C = img.shape
    dirs = np.array([[core_svf.pixel_direction(r, c, R, C) for c in range(C)] for r in range(R)]).reshape(-1, 3)
    v = img.reshape(-1)
    if v.all() or not v.any():
        return np.full(v.shape, math.pi if v.all() else -math.pi)
    chord = np.linalg.norm(dirs[:, None, :] - dirs[None, :, :], axis=2)
    gamma = 2.0 * np.arcsin(np.minimum(1.0, chord / 2.0))
    gamma[v[:, None] == v[None, :]] = np.inf
    g = gamma.min(axis=1)
    m = np.maximum(g - 0.5 * math.pi / R, 0.5 * g)
    return np.where(v == 1, m, -m)


def _random_images(rng, R, C, n):
    out = []
    for i in range(n):
        if i % 3 == 0:      # noise
            img = rng.uniform(size=(R, C)) < rng.uniform(0.05, 0.95)
        else:               # smooth blobs: a random low-order field thresholded
            th = (np.arange(R) + 0.5) * math.pi / R
            ph = (np.arange(C) + 0.5) * 2 * math.pi / C
            f = sum(rng.normal() * np.cos(a * th[:, None] + rng.uniform(0, 6))
                    * np.cos(b * ph[None, :] + rng.uniform(0, 6))
                    for a, b in rng.integers(0, 4, (5, 2)))
            img = f > rng.normal(0, 0.5)
        out.append(img.astype(np.uint8))
    out.append(np.ones((R, C), np.uint8))
    out.append(np.zeros((R, C), np.uint8))
    one = np.zeros((R, C), np.uint8)
    one[0, 3] = 1         # a single pixel at the pole
    out.append(one)
    return np.array(out)


@pytest.mark.parametrize("R,C", [(16, 16), (12, 20), (9, 7), (32, 32), (20, 40)])
def test_ssdf_matches_brute_force(R, C):
    """Reference: nearest opposite pixel over all pixel pairs by the angle between their centres
    (``_brute_ssdf``); the value +-max(gamma - delta/2, gamma/2), +-pi for uniform images."""
    imgs = _random_images(np.random.default_rng(R * 100 + C), R, C, 12)
    got = svf.ssdf_images(svf.pack_images(imgs), R, C)
    assert got.dtype == np.float32 and got.shape == (len(imgs), R * C)
    for i, img in enumerate(imgs):
        ref = _brute_ssdf(img)
        assert np.allclose(got[i], ref, rtol=1e-6, atol=1e-7), (i, np.abs(got[i] - ref).max())


def test_ssdf_sign_reproduces_the_images(tiny_svf):
    """Reference: the visibility images themselves (sign + visible, - occluded, never 0); the bilinear
    lookup at pixel centres gives the pixel, and between two row neighbours across a boundary (both at
    +-delta/2, delta = pi / res_theta) the zero crossing lies midway."""
    _, _, packed = tiny_svf
    X = svf.ssdf_images(packed, RES, RES)
    img = svf.unpack_images(packed, RES, RES).reshape(len(packed), -1)
    assert np.array_equal(X > 0, img == 1) and not (X == 0).any()
    s = int(np.argmax([(0 < im.sum() < im.size) for im in img]))
    x = X[s].astype(np.float64)
    for r, c in [(0, 0), (5, 31), (16, 7), (31, 13)]:
        w = np.array(core_svf.pixel_direction(r, c, RES, RES))
        assert core_svf.image_at(x, RES, RES, w) == pytest.approx(x[r * RES + c], abs=1e-12)
    found = 0
    for r in range(RES - 1):
        th = (r + 1.0) * math.pi / RES                    # midway between rows r and r + 1
        if math.sin(th) < 0.55:                            # near the poles a row neighbour is nearer
            continue
        for c in range(RES):
            if img[s, r * RES + c] != img[s, (r + 1) * RES + c]:
                found += 1
                ph = (c + 0.5) * 2 * math.pi / RES
                w = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])
                assert abs(x[r * RES + c]) == abs(x[(r + 1) * RES + c]) == pytest.approx(0.5 * math.pi / RES)
                assert abs(core_svf.image_at(x, RES, RES, w)) < 1e-6
    assert found > 0


# ------------------------------------------------------------------------------------------------ 3. PCA
def _exact_pca(X):
    Xd = X.astype(np.float64)
    mu = Xd.mean(axis=0)
    _, s, Vt = np.linalg.svd(Xd - mu, full_matrices=False)
    return mu, s * s / len(X), Vt


def test_pca_matches_exact_svd(tiny_svf):
    """Reference: numpy's SVD of the whole centred SSDF matrix (288 segments, D = 1024): with enough
    power iterations the randomised PCA gives its mean, leading eigenvalues and basis rows; at the
    defaults (2 power iterations) its reconstruction error is within 2 % of the optimum; the basis is
    orthonormal."""
    _, _, packed = tiny_svf
    X = svf.ssdf_images(packed, RES, RES)
    mu, ev, Vt = _exact_pca(X)
    n = 8
    pca = svf.ssdf_pca(packed, RES, RES, n, seed=3, power_iters=8, chunk=100)
    assert pca.mean.dtype == np.float32 and pca.basis.shape == (n, RES * RES) and pca.basis.dtype == np.float32
    assert np.allclose(pca.mean, mu, rtol=1e-6, atol=1e-6)
    assert np.allclose(pca.eigenvalues, ev[:n], rtol=1e-7)
    assert pca.variance == pytest.approx(ev.sum(), rel=1e-9)
    gap = np.flatnonzero(np.diff(-ev[:n + 1]) > 0.05 * ev[:n])   # components separated from the next
    B = pca.basis.astype(np.float64)
    assert np.all(np.abs((B[gap] * Vt[gap]).sum(axis=1)) > 1 - 1e-5)
    assert np.abs(B @ B.T - np.eye(n)).max() < 1e-6
    for n in (16, 48):
        pca = svf.ssdf_pca(packed, RES, RES, n, seed=3)
        _, parts = svf.ssdf_project(packed, RES, RES, pca.mean, pca.basis)
        rms = svf.pca_error_report(parts)["rms_error"]
        assert rms <= 1.02 * math.sqrt(ev[n:].sum() / (RES * RES)) + 1e-6


def test_pca_error_falls_and_signs_hold_outside_the_boundary_band(tiny_svf):
    """Reference: the images; the RMS error of the reconstruction falls with the number of components,
    the reconstructed sign differs only next to the image boundary (outside the one-pixel band: < 0.1 %
    of pixels at 48 components), and with as many components as segments the reconstruction is exact
    up to float32 (no sign wrong anywhere)."""
    _, _, packed = tiny_svf
    reports = []
    for n in (2, 8, 24, 48, len(packed)):
        pca = svf.ssdf_pca(packed, RES, RES, n, seed=1)
        coeffs, parts = svf.ssdf_project(packed, RES, RES, pca.mean, pca.basis)
        assert coeffs.shape == (len(packed), n) and coeffs.dtype == np.float32
        reports.append(svf.pca_error_report(parts))
    rms = [r["rms_error"] for r in reports]
    assert all(a > b for a, b in zip(rms, rms[1:]))
    assert reports[3]["sign_error_outside_band"] < 1e-3
    assert reports[-1]["sign_error"] == 0 and reports[-1]["rms_error"] < 1e-5
    img = svf.unpack_images(packed, RES, RES)
    assert reports[0]["visible_fraction"] == pytest.approx(img.mean(), abs=1e-12)
    X = svf.ssdf_images(packed, RES, RES).astype(np.float64)
    assert reports[0]["rel_error"] == pytest.approx(rms[0] / math.sqrt((X * X).mean()), rel=1e-9)


def test_pca_is_chunk_and_storage_independent(tiny_svf):
    """Reference: the PCA streamed in chunks of 100 segments; held in memory, in chunks of 7 or with the
    segments shuffled, the same bytes; projecting chunk by chunk gives the rows and (summed in chunk
    order) the partials of the whole."""
    _, _, packed = tiny_svf
    a = svf.ssdf_pca(packed, RES, RES, 12, seed=5, chunk=100)
    shuffled = packed[np.random.default_rng(0).permutation(len(packed))]
    for pk, kw in ((packed, {"hold": True}), (packed, {"chunk": 7}), (shuffled, {})):
        b = svf.ssdf_pca(pk, RES, RES, 12, seed=5, **kw)
        assert a.mean.tobytes() == b.mean.tobytes() and a.basis.tobytes() == b.basis.tobytes()
        assert a.eigenvalues.tobytes() == b.eigenvalues.tobytes()
    full, parts = svf.ssdf_project(packed, RES, RES, a.mean, a.basis)
    c1, p1 = svf.ssdf_project(packed[:150], RES, RES, a.mean, a.basis)
    c2, p2 = svf.ssdf_project(packed[150:], RES, RES, a.mean, a.basis)
    assert np.array_equal(np.vstack([c1, c2]), full)
    assert np.allclose(p1 + p2, parts, rtol=1e-12)
    small = svf.svf_memory_estimate(len(packed), RES, RES, 12, hold=False, chunk=100)
    assert small < svf.svf_memory_estimate(len(packed), RES, RES, 12, hold=True)
    assert svf.svf_memory_estimate(25000, 128, 128, 48, hold=True) > 25000 * 128 * 128 * 4


def test_unique_images_match_numpy_unique(tiny_svf):
    """Reference: np.unique(axis=0) (rows in lexicographic byte order, inverse, counts), also for rows
    whose length is not a multiple of 8 bytes."""
    _, _, packed = tiny_svf
    for pk in (packed, packed[:, :37]):
        u, inv, cnt = svf.unique_images(pk)
        ru, rinv, rcnt = np.unique(pk, axis=0, return_inverse=True, return_counts=True)
        assert np.array_equal(u, ru) and np.array_equal(inv, rinv.reshape(-1)) and np.array_equal(cnt, rcnt)
        assert np.array_equal(u[inv], pk)


# ------------------------------------------------------------------------------------------------ 4. sums of SGs
def test_sg_weights_are_the_visible_solid_angle_per_nearest_axis(tiny_svf):
    """Reference: brute force in numpy (each visible pixel's solid angle to the axis of largest dot
    product, axes from stages.core.sg with the stored angle); the weights add up to the visible solid
    angle; angles depend only on (seed, segment id)."""
    seg, _, packed = tiny_svf
    angles, weights = svf.sg_fit(packed, seg.ids, RES, RES, 48, seed=9)
    assert angles.dtype == np.float32 and weights.shape == (len(packed), 48) and weights.dtype == np.float32
    img = svf.unpack_images(packed, RES, RES).reshape(len(packed), -1)
    dirs = np.array([[core_svf.pixel_direction(r, c, RES, RES) for c in range(RES)] for r in range(RES)]).reshape(-1, 3)
    omega = np.repeat([core_svf.pixel_solid_angle(r, RES, RES) for r in range(RES)], RES)
    assert omega.sum() == pytest.approx(4 * math.pi, rel=1e-12)
    visible = img @ omega
    assert np.allclose(weights.astype(np.float64).sum(axis=1), visible, rtol=1e-6, atol=1e-7)
    for s in np.flatnonzero(img.sum(axis=1) > 0)[:10]:
        axes = spherical_fibonacci_axes(48, float(angles[s]))
        near = np.argmax(dirs @ axes.T, axis=1)
        ref = np.bincount(near[img[s] == 1], weights=omega[img[s] == 1], minlength=48)
        assert np.allclose(weights[s], ref, rtol=1e-6, atol=1e-9)
        assert np.array_equal(svf.sg_axes(angles[s], 48), axes)
    a2, w2 = svf.sg_fit(packed[40:60], seg.ids[40:60], RES, RES, 48, seed=9)
    assert np.array_equal(a2, angles[40:60]) and np.array_equal(w2, weights[40:60])
    assert len(np.unique(angles)) == len(angles)


def test_ssg_visibility_integrates_to_the_weights():
    """Reference: the definition sum_q w_q G(w; xi_q, lam) / M(lam) evaluated in numpy, and its integral
    over the sphere (midpoint rule, 512 x 1024) = sum_q w_q (normalised SGs)."""
    rng = np.random.default_rng(4)
    axes = spherical_fibonacci_axes(48, 0.7)
    w = rng.uniform(0, 0.3, 48)
    lam = 128.0
    for _ in range(5):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        ref = (w * np.exp(lam * (axes @ d - 1))).sum() / (2 * math.pi * (1 - math.exp(-2 * lam)) / lam)
        assert core_svf.ssg_visibility(axes, w, lam, d) == pytest.approx(ref, rel=1e-12)
    nt, nph = 512, 1024
    th = (np.arange(nt) + 0.5) * math.pi / nt
    ph = (np.arange(nph) + 0.5) * 2 * math.pi / nph
    D = np.stack([np.outer(np.sin(th), np.cos(ph)), np.outer(np.sin(th), np.sin(ph)),
                  np.outer(np.cos(th), np.ones(nph))], axis=-1).reshape(-1, 3)
    dA = np.repeat(np.sin(th) * (math.pi / nt) * (2 * math.pi / nph), nph)
    vals = (np.exp(lam * (D @ axes.T - 1)) @ w) / sg_mass(lam)
    assert (vals * dA).sum() == pytest.approx(w.sum(), rel=1e-3)


# ------------------------------------------------------------------------------------------------ 5. lookups
def test_reconstruction_lookups_agree(tiny_svf):
    """Reference: ``ssdf_reconstruct``'s full image: ``ssdf_at`` (four pixels) equals ``image_at`` on
    it at random directions and the pixel at pixel centres; ``ssdf_visible`` is its sign."""
    _, _, packed = tiny_svf
    pca = svf.ssdf_pca(packed, RES, RES, 16, seed=2)
    coeffs, _ = svf.ssdf_project(packed, RES, RES, pca.mean, pca.basis)
    rng = np.random.default_rng(6)
    out = np.empty(RES * RES)
    for s in rng.integers(0, len(packed), 4):
        core_svf.ssdf_reconstruct(pca.mean, pca.basis, coeffs[s], out)
        for _ in range(50):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            v = core_svf.ssdf_at(pca.mean, pca.basis, coeffs[s], RES, RES, d)
            assert v == pytest.approx(core_svf.image_at(out, RES, RES, d), abs=1e-9)
            assert core_svf.ssdf_visible(pca.mean, pca.basis, coeffs[s], RES, RES, d) == (v > 0)
        r, c = 3, 30
        d = np.array(core_svf.pixel_direction(r, c, RES, RES))
        assert core_svf.ssdf_at(pca.mean, pca.basis, coeffs[s], RES, RES, d) == pytest.approx(out[r * RES + c],
                                                                                             abs=1e-9)


# ------------------------------------------------------------------------------------------------ determinism
def test_bytes_identical_at_one_and_two_threads(tiny_tiling):
    """Reference: the same chunk kernels and PCA run at 1 thread; at 2 threads every output byte equal."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here (NUMBA_NUM_THREADS=1)")
    _, sc, art = tiny_tiling
    seg = _segments(art, 1)
    psc = periodic_scene(sc, 1)
    sel = slice(0, 400)
    n0 = numba.get_num_threads()
    outs = []
    try:
        for t in (1, 2):
            numba.set_num_threads(t)
            packed = svf.visibility_images(psc, 1, seg.z_lo, seg.z_hi, seg.mids[sel], seg.fibre[sel], 24, 24)
            pca = svf.ssdf_pca(packed, 24, 24, 10, seed=7, chunk=64)
            coeffs, parts = svf.ssdf_project(packed, 24, 24, pca.mean, pca.basis)
            angles, weights = svf.sg_fit(packed, seg.ids[sel], 24, 24, 48, seed=7)
            outs.append([packed, pca.mean, pca.basis, pca.eigenvalues, coeffs, parts, angles, weights])
    finally:
        numba.set_num_threads(n0)
    for a, b in zip(*outs):
        assert a.tobytes() == b.tobytes()

