"""3. PCA of the SSDFs (the package doc): the distinct images, weighted by their count, through the deterministic
randomised subspace iteration of ``stages.precompute.pca``; the projection of each segment and the error report."""

import math
from collections import namedtuple

import numba
import numpy as np
from numba import njit, prange

from stages.precompute.pca import subspace_pca
from stages.precompute.svf.pixels import packed_bytes
from stages.precompute.svf.ssdf import segment_ssdf, ssdf_images, ssdf_tables

SsdfPca = namedtuple("SsdfPca", ["mean", "basis", "eigenvalues", "variance", "segments"])
SsdfPca.__doc__ = """ssdf_pca's result: mean (D,) float32, basis (n, D) float32 (orthonormal rows),
eigenvalues (n,) float64 (variance per segment along each row), variance (total variance per segment,
float), segments (S)."""


def svf_memory_estimate(S: int, res_theta: int, res_phi: int, n_components: int, *, hold: bool = True,
                        chunk: int = 1024, oversample: int = 8, threads: int | None = None) -> int:
    """Peak bytes of the global PCA step (``ssdf_pca``) for S segments, with ``hold`` the (S, D) float32
    SSDF matrix in memory, else streamed in chunks of ``chunk`` images; includes the packed images
    and the outputs (mean, basis, coefficients). Worst case: every image distinct."""
    D = int(res_theta) * int(res_phi)
    p = int(n_components) + int(oversample)
    threads = threads or numba.get_num_threads()
    rows = S if hold else min(int(chunk), S)
    packed = S * packed_bytes(res_theta, res_phi)
    dense = rows * D * 4
    vectors = 3 * D * p * 8 + min(int(chunk), S) * p * 8 + 4 * p * p * 8 + 2 * D * 8
    outputs = S * n_components * 4 + n_components * D * 4 + D * 4
    scratch = threads * (D * (1 + 8 + 8) + 8 * res_theta * res_phi)
    return int(packed + dense + vectors + outputs + scratch)


def _chunks(S, chunk):
    return [(a, min(S, a + chunk)) for a in range(0, S, chunk)]


def unique_images(packed):
    """(unique rows (u, B) in lexicographic order of their bytes, inverse (S,) int64, counts (u,) int64)
    of bit-packed images: identical images have identical SSDFs (the damask's fully occluded segments
    are about 60 % of them), so the PCA and the projection work on distinct images only. A lexsort on
    big-endian 64-bit words (np.unique(axis=0) sorts 2 kB void records ~70x slower)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    S, B = packed.shape
    if S == 0:
        return packed, np.zeros(0, np.int64), np.zeros(0, np.int64)
    pad = (-B) % 8
    words = np.ascontiguousarray(np.pad(packed, ((0, 0), (0, pad))) if pad else packed).view(">u8")
    order = np.lexsort(words.T[::-1])
    ws = words[order]
    new = np.ones(S, bool)
    new[1:] = np.any(ws[1:] != ws[:-1], axis=1)
    group = np.cumsum(new) - 1
    inverse = np.empty(S, np.int64)
    inverse[order] = group
    return np.ascontiguousarray(packed[order[new]]), inverse, np.bincount(group).astype(np.int64)


def ssdf_pca(packed, res_theta: int, res_phi: int, n_components: int = 48, seed: int = 0,
             oversample: int = 8, power_iters: int = 2, chunk: int = 1024, hold: bool = False) -> SsdfPca:
    """Global. PCA of the SSDFs of all segments of an exemplar (module doc) from their bit-packed
    images (S, ceil(D/8)). Distinct images are processed once, weighted by their count, in
    lexicographic order of their bytes. The bytes depend neither on ``chunk``, ``hold``, the order of
    the segments nor the thread count."""
    packed = np.ascontiguousarray(packed, np.uint8)
    S = packed.shape[0]
    D = res_theta * res_phi
    if S < 1:
        raise ValueError("ssdf_pca needs at least one segment")
    n = int(n_components)
    if not 1 <= n <= D:
        raise ValueError(f"n_components must be in 1..{D}, got {n}")
    uniq, _, counts = unique_images(packed)
    m = counts.astype(np.float64)
    parts = _chunks(len(uniq), max(1, int(chunk)))
    X_all = ssdf_images(uniq, res_theta, res_phi) if hold else None

    def blocks():
        for a, b in parts:
            yield (X_all[a:b] if hold else ssdf_images(uniq[a:b], res_theta, res_phi)), m[a:b]

    pca = subspace_pca(blocks, S, D, n, seed, oversample, power_iters)
    return SsdfPca(pca.mean.astype(np.float32), pca.basis.astype(np.float32), pca.eigenvalues, pca.variance, S)


@njit(cache=True, parallel=True)
def _project_kernel(packed, R, C, mean, basis, basis_t, coeffs, parts):
    """Per segment: SSDF, coefficients (float32), and error partials of the reconstruction from the
    float32 coefficients: [err^2, ssdf^2, pixels, sign wrong, sign wrong outside band, pixels outside
    band, visible pixels]. basis_t = basis.T (D, n): the loops run along contiguous memory with one
    accumulator per output entry (sums in d, resp. j, ascending, as ``ssdf_reconstruct``)."""
    tabs = ssdf_tables(R, C)
    D = R * C
    n = basis.shape[0]
    for s in prange(packed.shape[0]):
        img, buf = segment_ssdf(packed, s, R, C, tabs)
        x = np.empty(D)
        for d in range(D):
            x[d] = np.float32(buf[d])          # the SSDF as the PCA saw it
        acc = np.zeros(n)
        for d in range(D):
            xc = x[d] - mean[d]
            for j in range(n):
                acc[j] += xc * basis_t[d, j]
        c32 = np.empty(n)
        for j in range(n):
            c32[j] = np.float32(acc[j])
            coeffs[s, j] = c32[j]
        y = np.empty(D)
        for d in range(D):
            y[d] = np.float64(mean[d])
        for j in range(n):
            cj = c32[j]
            for d in range(D):
                y[d] += cj * basis[j, d]
        e2 = 0.0
        x2 = 0.0
        wrong = 0.0
        wrong_out = 0.0
        outside = 0.0
        vis = 0.0
        for r in range(R):
            for c in range(C):
                i = r * C + c
                e = y[i] - x[i]
                e2 += e * e
                x2 += x[i] * x[i]
                v = img[i]
                vis += v
                band = False
                for a in range(-1, 2):
                    rr = r + a
                    if rr < 0 or rr >= R:
                        continue
                    for b in range(-1, 2):
                        cc = (c + b) % C
                        if img[rr * C + cc] != v:
                            band = True
                if not band:
                    outside += 1.0
                if (y[i] > 0.0) != (v == 1):
                    wrong += 1.0
                    if not band:
                        wrong_out += 1.0
        parts[s, 0] = e2
        parts[s, 1] = x2
        parts[s, 2] = D
        parts[s, 3] = wrong
        parts[s, 4] = wrong_out
        parts[s, 5] = outside
        parts[s, 6] = vis


N_PARTIALS = 7


def ssdf_project(packed, res_theta: int, res_phi: int, mean, basis):
    """Chunk level. (coeffs (s, n) float32, error partials (7,) float64) of the segments' SSDFs on the
    PCA (mean, basis as stored, float32). Add the partials of all chunks in chunk order and pass the
    sum to ``pca_error_report``. Each row depends only on the segment's image (distinct images are
    computed once)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    mean = np.ascontiguousarray(mean, np.float32)
    basis = np.ascontiguousarray(basis, np.float32)
    S = packed.shape[0]
    n = basis.shape[0]
    if S == 0:
        return np.zeros((0, n), np.float32), np.zeros(N_PARTIALS)
    uniq, inv, _ = unique_images(packed)
    cu = np.zeros((len(uniq), n), np.float32)
    pu = np.zeros((len(uniq), N_PARTIALS))
    with numba.parallel_chunksize(1):
        _project_kernel(uniq, res_theta, res_phi, mean, basis, np.ascontiguousarray(basis.T), cu, pu)
    parts = pu[inv]
    total = np.zeros(N_PARTIALS)
    for s in range(S):          # ascending, whatever the threads
        total += parts[s]
    return cu[inv], total


def pca_error_report(partials) -> dict:
    """From summed ``ssdf_project`` partials: rms_error (radians, over all pixels and segments),
    rel_error (rms_error / RMS of the SSDFs), sign_error (fraction of pixels whose reconstructed sign
    differs from the image), sign_error_outside_band (the same among pixels with no opposite
    8-neighbour), visible_fraction."""
    e2, x2, npx, wrong, wrong_out, outside, vis = (float(v) for v in partials)
    npx = max(npx, 1.0)
    rms = math.sqrt(e2 / npx)
    return {"rms_error": rms,
            "rel_error": rms / math.sqrt(x2 / npx) if x2 > 0 else 0.0,
            "sign_error": wrong / npx,
            "sign_error_outside_band": wrong_out / outside if outside > 0 else 0.0,
            "visible_fraction": vis / npx}
