"""Principal components of weighted rows, deterministic: randomised subspace iteration (Halko, Martinsson and
Tropp 2011, Alg. 4.4 with a Gram eigenproblem at the end) whose every reduction runs in a fixed order, so the
bytes depend neither on the thread count nor on how the rows are split into blocks.

``subspace_pca(blocks, total_weight, D, n, seed, oversample, power_iters)`` reads the rows through ``blocks()``,
a callable that yields (X (rows, D), m (rows,)) blocks in a fixed order -- row s of weight m[s] (a count of
identical rows, or 1) -- as many times as the iteration needs (2 + power_iters passes), so a caller may stream
rows it cannot hold. It returns a ``Pca``: the weighted mean (D,), n orthonormal rows (n, D) sorted by falling
variance (each row's sign fixed: its largest-magnitude entry positive), the variance along each per unit weight,
and the total variance per unit weight -- all float64.

Steps: the weighted mean; Z (D, p), p = min(D, n + oversample), from standard normals ``normal(seed, d, 2 j)``,
orthonormalised; ``power_iters`` times Z <- orth((X - mean)^T M (X - mean) Z); then the Gram matrix
G = W^T M W of W = (X - mean) Z, its eigenvectors U, and the basis rows (Z U)^T of the n largest. A row of Z
that vanishes (rank below p) is replaced by fresh normals and orthonormalised again, so the basis is
orthonormal whatever the rank; rows past the rank then carry zero variance.

Users: the SVF's SSDF compression (``stages.precompute.svf.pca``, Khungurn et al. 2017 §4.1) and the tabulated
BTF's local PCA (``stages.precompute.btf_compress``).
"""

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from stages.core.rng import normal

Pca = namedtuple("Pca", ["mean", "basis", "eigenvalues", "variance"])
Pca.__doc__ = """subspace_pca's result: mean (D,), basis (n, D) orthonormal rows, eigenvalues (n,) variance per unit
weight along each row, variance (float) the total variance per unit weight; float64."""

BLOCK = 32   # columns per block of acc_mean / acc_xtw: one thread sums a block's columns over the rows in order


@njit(cache=True)
def column_block(b, D):
    """Columns [d0, d1) of block ``b`` of D columns cut into blocks of BLOCK."""
    d0 = b * BLOCK
    return d0, min(D, d0 + BLOCK)


@njit(cache=True, parallel=True)
def acc_mean(X, m, acc):
    """acc[d] += m[s] X[s, d], s ascending."""
    S, D = X.shape
    for b in prange((D + BLOCK - 1) // BLOCK):
        d0, d1 = column_block(b, D)
        for s in range(S):
            for d in range(d0, d1):
                acc[d] += m[s] * X[s, d]


@njit(cache=True, parallel=True)
def times_z(X, mean, Z, W):
    """W[s, :] = (X[s] - mean) Z  (Z (D, p)), d ascending."""
    S, D = X.shape
    p = Z.shape[1]
    for s in prange(S):
        acc = np.zeros(p)
        for d in range(D):
            x = X[s, d] - mean[d]
            for j in range(p):
                acc[j] += x * Z[d, j]
        for j in range(p):
            W[s, j] = acc[j]


@njit(cache=True, parallel=True)
def acc_xtw(X, m, mean, W, Y, sq):
    """Y[d, :] += m[s] (X[s, d] - mean[d]) W[s, :] and sq[d] += m[s] (X[s, d] - mean[d])^2, s ascending."""
    S, D = X.shape
    p = W.shape[1]
    for b in prange((D + BLOCK - 1) // BLOCK):
        d0, d1 = column_block(b, D)
        for s in range(S):
            for d in range(d0, d1):
                x = X[s, d] - mean[d]
                mx = m[s] * x
                sq[d] += mx * x
                for j in range(p):
                    Y[d, j] += mx * W[s, j]


@njit(cache=True)
def acc_gram(W, m, G):
    """G[i, j] += m[s] W[s, i] W[s, j], s ascending."""
    S, p = W.shape
    for s in range(S):
        for i in range(p):
            w = m[s] * W[s, i]
            for j in range(p):
                G[i, j] += w * W[s, j]


@njit(cache=True)
def orthonormalise(Zt, seed, salt):
    """Rows of Zt (p, D) orthonormalised in place by modified Gram-Schmidt, twice; a row that vanishes
    (rank deficiency) is replaced by normals from rng (seed, salt + row, ...) and orthonormalised again."""
    p, D = Zt.shape
    for j in range(p):
        for attempt in range(4):
            n0 = 0.0
            for d in range(D):
                n0 += Zt[j, d] * Zt[j, d]
            n0 = math.sqrt(n0)
            for _rep in range(2):
                for i in range(j):
                    rr = 0.0
                    for d in range(D):
                        rr += Zt[i, d] * Zt[j, d]
                    for d in range(D):
                        Zt[j, d] -= rr * Zt[i, d]
            nn = 0.0
            for d in range(D):
                nn += Zt[j, d] * Zt[j, d]
            nn = math.sqrt(nn)
            if nn > 1e-10 * n0 and nn > 0.0:
                for d in range(D):
                    Zt[j, d] /= nn
                break
            for d in range(D):
                Zt[j, d] = normal(seed, salt + 1000003 * (attempt + 1) + j, 2 * d)


@njit(cache=True)
def omega(seed, D, p, out):
    """out (p, D): standard normals normal(seed, d, 2 j)."""
    for d in range(D):
        for j in range(p):
            out[j, d] = normal(seed, d, 2 * j)


@njit(cache=True)
def basis_rows(Zt, U, out):
    """out[k, d] = sum_j Zt[j, d] U[j, k], j ascending."""
    p, D = Zt.shape
    n = out.shape[0]
    for k in range(n):
        for d in range(D):
            acc = 0.0
            for j in range(p):
                acc += Zt[j, d] * U[j, k]
            out[k, d] = acc


def subspace_pca(blocks, total_weight: float, D: int, n: int, seed: int = 0, oversample: int = 8,
                 power_iters: int = 2) -> Pca:
    """The n leading principal components of the weighted rows ``blocks()`` yields (module doc)."""
    p = min(D, n + int(oversample))
    acc = np.zeros(D)
    for X, mb in blocks():
        acc_mean(X, mb, acc)
    mean = acc / total_weight
    Zt = np.empty((p, D))
    omega(int(seed), D, p, Zt)
    orthonormalise(Zt, int(seed), 1 << 40)
    sq = np.zeros(D)
    for it in range(max(0, int(power_iters))):
        Z = np.ascontiguousarray(Zt.T)
        Y = np.zeros((D, p))
        sq[:] = 0.0
        for X, mb in blocks():
            W = np.empty((X.shape[0], p))
            times_z(X, mean, Z, W)
            acc_xtw(X, mb, mean, W, Y, sq)
        Zt = np.ascontiguousarray(Y.T)
        orthonormalise(Zt, int(seed), (it + 2) << 40)
    Z = np.ascontiguousarray(Zt.T)
    G = np.zeros((p, p))
    if power_iters <= 0:
        sq[:] = 0.0
    for X, mb in blocks():
        W = np.empty((X.shape[0], p))
        times_z(X, mean, Z, W)
        acc_gram(W, mb, G)
        if power_iters <= 0:
            acc_xtw(X, mb, mean, W, np.zeros((D, p)), sq)
    evals, U = np.linalg.eigh(G)
    order = np.argsort(-evals, kind="stable")[:n]
    U = np.ascontiguousarray(U[:, order])
    basis = np.empty((n, D))
    basis_rows(Zt, U, basis)
    big = np.argmax(np.abs(basis), axis=1)
    basis *= np.where(basis[np.arange(n), big] < 0.0, -1.0, 1.0)[:, None]
    return Pca(mean, basis, np.maximum(evals[order], 0.0) / total_weight, float(sq.sum()) / total_weight)
