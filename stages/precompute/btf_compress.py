"""The tabulated cloth texture: every texel's acquired samples kept as a table over (view, light, channel),
compressed by local PCA (Müller, Meseth and Klein 2003, "Compression and real-time rendering of measured BTFs
using local PCA", §3-4: clustered principal components), beside seed 002's Lafortune fit.

Why a table: the fit's family (Lafortune lobes times T(v), ``stages.precompute.btf_fit``) cannot follow a
fibre's narrow glints; the acquired samples hold them as well as the grids resolve them. Stored as they are
they are large (32 x 32 texels and their mip levels x 64 views x 64 lights x 3 channels: 67 MB an exemplar
in float32), so they are compressed.

What it compresses
------------------
The rows x_t (D = V L 3 values: view-major, then light, then channel) of T texels -- ``precompute btf`` passes
every mip level's texels of one exemplar (the alpha-weighted means of ``btf_fit.group_level``), finest level
first. The model (Müller et al. 2003 Eq. 3) is

    x_t ~ m_c + sum_{k < K} w_tk b_ck,     c = cluster(t),

C clusters, each with its mean m_c (D,) and K orthonormal rows b_ck (D,), and per texel its cluster and K
weights. Storage: C (K + 1) D + T K floats and T cluster indices.

Algorithm (``compress_texels``)
-------------------------------
1. **Global start.** The K leading components of all rows (``stages.precompute.pca.subspace_pca``); each
   row's coefficients on them.
2. **Clusters in coefficient space.** k-means (Lloyd) on those coefficients, seeded by farthest points: the
   first centre is the row of largest coefficient norm, each next the row farthest from the centres chosen
   (ties: the lowest row). At most ``KMEANS_ITERATIONS`` rounds, or until no row moves.
3. **Local rounds** (Müller et al.'s iteration): the K leading components of each cluster's rows, then each
   row moves to the cluster whose mean and components reconstruct it best (squared error ||x - m_c||^2 -
   sum_k (b_ck . (x - m_c))^2, ties to the lowest cluster); until no row moves, or ``rounds`` rounds. A cluster
   left empty takes the row reconstructed worst by its own cluster. The components of the final clusters are
   computed once more if the last round moved rows.
4. **Weights**: w_tk = b_ck . (x_t - m_c), stored as float32.

Every sum runs in a fixed order (the PCA's kernels and this module's), so the bytes depend neither on the
thread count nor on where the rows came from. C = 1 is plain PCA (the alternative the measurements compare).

Errors: ``rel_rmse_by_components`` (K + 1,) is sqrt(sum_t ||x_t - x_t^(k)||^2 / sum_t ||x_t||^2) for the
reconstruction from the first k components of each cluster (k = 0: the cluster means alone), from the float64
coefficients; ``rel_rmse`` the same for all K components from the stored (float32) parameters
(``stages.core.btf.decode_texels``). The first never rises with k: the rows are orthonormal.

Bounds: 1 <= K <= the rows' rank bound min(T - 1, D) (the centred rows span at most T - 1 dimensions; a
component past it carries nothing) and 1 <= C <= T; ``compress_texels`` raises ValueError past them.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from stages.core.btf import decode_texels
from stages.precompute.pca import subspace_pca

KMEANS_ITERATIONS = 50
LOCAL_ROUNDS = 8        # Müller et al. 2003 converge in a few rounds; the acquired satins and knit settle in 5-6

TabulatedBtf = namedtuple("TabulatedBtf", ["cluster", "mean", "basis", "weights", "rel_rmse_by_components",
                                           "rel_rmse", "rounds"])
TabulatedBtf.__doc__ = """compress_texels's result: cluster (T,) int32, mean (C, D) float32, basis (C, K, D) float32
(orthonormal rows per cluster), weights (T, K) float32, rel_rmse_by_components (K + 1,) and rel_rmse (float): the
relative errors of the module doc; rounds, the local rounds run."""


def rank_bound(rows: int, dims: int) -> int:
    """The largest useful component count of ``rows`` rows of ``dims`` values: min(rows - 1, dims), at least 1."""
    return max(1, min(int(rows) - 1, int(dims)))


@njit(cache=True, parallel=True)
def project_rows(X, rows, mean, basis, out):
    """out[i, k] = basis[k] . (X[rows[i]] - mean) (float64, d ascending)."""
    K, D = basis.shape
    for i in prange(rows.shape[0]):
        t = rows[i]
        for k in range(K):
            acc = 0.0
            for d in range(D):
                acc += basis[k, d] * (np.float64(X[t, d]) - mean[d])
            out[i, k] = acc


@njit(cache=True, parallel=True)
def cluster_errors(X, means, bases, out):
    """out[t, c] = ||X[t] - m_c||^2 - sum_k (b_ck . (X[t] - m_c))^2: the squared error of row t reconstructed by
    cluster c's mean and components (never below 0)."""
    T, D = X.shape
    C, K, _ = bases.shape
    for t in prange(T):
        x = np.empty(D)
        for c in range(C):
            e = 0.0
            for d in range(D):
                x[d] = np.float64(X[t, d]) - means[c, d]
                e += x[d] * x[d]
            for k in range(K):
                p = 0.0
                for d in range(D):
                    p += bases[c, k, d] * x[d]
                e -= p * p
            out[t, c] = max(e, 0.0)


def _farthest_points(P: np.ndarray, C: int) -> np.ndarray:
    """Indices of C seed rows of P (module doc, step 2)."""
    first = int(np.argmax(np.sum(P * P, axis=1)))
    seeds = [first]
    dist = np.sum((P - P[first]) ** 2, axis=1)
    for _ in range(1, C):
        nxt = int(np.argmax(dist))
        seeds.append(nxt)
        dist = np.minimum(dist, np.sum((P - P[nxt]) ** 2, axis=1))
    return np.asarray(seeds, np.int64)


def _kmeans(P: np.ndarray, C: int) -> np.ndarray:
    """Lloyd's k-means of the rows of P from farthest-point seeds: each row's cluster (T,) int64."""
    centres = P[_farthest_points(P, C)].copy()
    label = np.full(len(P), -1, np.int64)
    for _ in range(KMEANS_ITERATIONS):
        d2 = np.sum((P[:, None, :] - centres[None, :, :]) ** 2, axis=2)
        new = np.argmin(d2, axis=1)
        if np.array_equal(new, label):
            break
        label = new
        for c in range(C):
            members = label == c
            if members.any():
                centres[c] = np.mean(P[members], axis=0)
    return label


def _refill_empty(label: np.ndarray, errors: np.ndarray, C: int) -> np.ndarray:
    """Each empty cluster takes the row its own cluster reconstructs worst (ties: the lowest row)."""
    label = label.copy()
    own = errors[np.arange(len(label)), label] if errors is not None else np.zeros(len(label))
    for c in range(C):
        if not np.any(label == c):
            counts = np.bincount(label, minlength=C)
            movable = counts[label] > 1
            t = int(np.argmax(np.where(movable, own, -1.0)))
            label[t] = c
            own[t] = -1.0
    return label


def _local_pcas(X, label, C, K, seed):
    """(means (C, D), bases (C, K, D)) float64: each cluster's K leading components."""
    D = X.shape[1]
    means = np.zeros((C, D))
    bases = np.zeros((C, K, D))
    for c in range(C):
        rows = np.flatnonzero(label == c)
        Xc = np.ascontiguousarray(X[rows])

        def blocks(Xc=Xc):
            yield Xc, np.ones(len(Xc))
        pca = subspace_pca(blocks, float(len(rows)), D, K, seed + c)
        means[c] = pca.mean
        bases[c] = pca.basis
    return means, bases


def compress_texels(X, clusters: int, components: int, seed: int = 0, rounds: int = LOCAL_ROUNDS) -> TabulatedBtf:
    """Local PCA of the rows of X (T, D) float32 (module doc)."""
    X = np.ascontiguousarray(X, np.float32)
    if X.ndim != 2 or X.shape[0] < 1 or X.shape[1] < 1:
        raise ValueError(f"rows must be (T, D) with T, D >= 1, got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("rows hold nan or inf")
    T, D = X.shape
    K, C = int(components), int(clusters)
    if not 1 <= K <= rank_bound(T, D):
        raise ValueError(f"components must be in 1..{rank_bound(T, D)} (the rows' rank bound), got {K}")
    if not 1 <= C <= T:
        raise ValueError(f"clusters must be in 1..{T} (the rows), got {C}")
    everything = np.arange(T, dtype=np.int64)

    def all_rows():
        yield X, np.ones(T)
    g = subspace_pca(all_rows, float(T), D, K, seed)
    coeffs = np.empty((T, K))
    project_rows(X, everything, g.mean, g.basis, coeffs)
    label = _refill_empty(_kmeans(coeffs, C), None, C) if C > 1 else np.zeros(T, np.int64)
    errors = np.empty((T, C))
    ran = 0
    means, bases = _local_pcas(X, label, C, K, seed)
    for _ in range(max(0, int(rounds)) if C > 1 else 0):
        ran += 1
        cluster_errors(X, means, bases, errors)
        new = _refill_empty(np.argmin(errors, axis=1), errors, C)
        if np.array_equal(new, label):
            break
        label = new
        means, bases = _local_pcas(X, label, C, K, seed)
    weights = np.empty((T, K))
    x2 = float(np.sum(np.square(X, dtype=np.float64)))
    err_k = np.zeros(K + 1)
    for c in range(C):
        rows = np.flatnonzero(label == c).astype(np.int64)
        w = np.empty((len(rows), K))
        project_rows(X, rows, means[c], bases[c], w)
        weights[rows] = w
        resid = np.sum((X[rows].astype(np.float64) - means[c]) ** 2, axis=1)
        err_k[0] += float(np.sum(resid))
        for k in range(K):
            resid = resid - w[:, k] ** 2
            err_k[k + 1] += float(np.sum(np.maximum(resid, 0.0)))
    out = TabulatedBtf(label.astype(np.int32), means.astype(np.float32), bases.astype(np.float32),
                       weights.astype(np.float32), np.sqrt(err_k / max(x2, 1e-300)), 0.0, ran)
    Y = np.empty((T, D), np.float32)
    decode_texels(out.cluster, out.mean, out.basis, out.weights, Y, False)
    e2 = float(np.sum((Y.astype(np.float64) - X) ** 2))
    return out._replace(rel_rmse=math.sqrt(e2 / max(x2, 1e-300)))
