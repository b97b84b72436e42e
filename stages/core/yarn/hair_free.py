"""Hair flyaways without stored per-hair data: seed 000 Algorithm 3 (§4.4.2).

The hairs of one ply of one yarn are n i.i.d. points (z1, ze) of a 2D domain: start z1 uniform on
[0, L] and z extent ze from N(mu, sigma) truncated to mu +- 3 sigma (independent, so the
probability of an axis-aligned cell is a product of two 1D probabilities). The point hierarchy is
an implicit quad-tree: a node (cell, hair index range [i0, i0 + n)) splits its cell into four
quadrants; every hair of the node draws its quadrant from the conditional cell probabilities with
random numbers seeded by (yarn, ply, node id, hair), which is a draw of the multinomial
(n1, n2, n3, n4); the index range is partitioned in that order. A node with one hair draws its
(z1, ze) from the cell-conditioned distribution (inverse CDF); a node at depth ``MAX_DEPTH`` draws
each of its hairs that way. Because every node is seeded consistently, the tree is the same for
every query: ``active_hairs`` (prune cells that cannot reach z, seed 000 D(z)) and
``all_hairs`` (visit everything: the hybrid mode's pre-generation and the realization) produce the
same hairs. A hair spans [min(z1, z2), max(z1, z2)], z2 = clamp(z1 + ze, 0, L); it is active at z
when z lies in that span grown by the margin m (Eq. 13 with m >= fibre radius).
"""
import math

import numpy as np
from numba import njit

from stages.core.dispatch import runtime_value
from stages.core.rng import hash_u64, uniform
from stages.core.shading.bcsdf import std_normal_quantile
from stages.core.yarn.model import CLAMP, STREAM_TREE

MAX_DEPTH = 24


@njit(cache=True)
def norm_cdf(x):
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


@njit(cache=True)
def _ze_cdf(mu, sig, v):
    if sig <= 0.0:
        return 0.0 if v < mu else 1.0
    return norm_cdf((v - mu) / sig)


@njit(cache=True)
def _draw_leaf(mu, sig, a, b, c, d, u1, u2):
    z1 = a + (b - a) * u1
    if sig <= 0.0:
        return z1, mu
    fc = _ze_cdf(mu, sig, c)
    fd = _ze_cdf(mu, sig, d)
    ze = mu + sig * std_normal_quantile(fc + (fd - fc) * u2)
    return z1, min(max(ze, c), d)


@njit(cache=True)
def _traverse(L, n_hairs, mu, sig, node_seed, z, margin, prune, out_idx, out_z1, out_ze):
    """Shared traversal; writes hairs (index, z1, ze) in index order, returns how many."""
    if n_hairs <= 0 or L <= 0.0:
        return 0
    if sig <= 0.0:
        ze_lo = mu
        ze_hi = mu
    else:
        ze_lo = mu - CLAMP * sig
        ze_hi = mu + CLAMP * sig
    cap = 4 * MAX_DEPTH + 8
    s_id = np.empty(cap, np.uint64)
    s_dep = np.empty(cap, np.int64)
    s_i0 = np.empty(cap, np.int64)
    s_n = np.empty(cap, np.int64)
    s_box = np.empty((cap, 4))
    top = 0
    s_id[0] = 1
    s_dep[0] = 0
    s_i0[0] = 0
    s_n[0] = n_hairs
    s_box[0, 0] = 0.0
    s_box[0, 1] = L
    s_box[0, 2] = ze_lo
    s_box[0, 3] = ze_hi
    top = 1
    count = 0
    counts = np.zeros(4, np.int64)
    p = np.zeros(4)
    while top > 0:
        top -= 1
        nid = s_id[top]
        dep = s_dep[top]
        i0 = s_i0[top]
        n = s_n[top]
        a = s_box[top, 0]
        b = s_box[top, 1]
        c = s_box[top, 2]
        d = s_box[top, 3]
        if n == 0:
            continue
        if prune:
            lo = a + min(c, 0.0)
            hi = b + max(d, 0.0)
            if z < max(lo, 0.0) - margin or z > min(hi, L) + margin:
                continue
        if n == 1 or dep >= MAX_DEPTH:
            key = hash_u64(node_seed, nid, STREAM_TREE)
            for i in range(n):
                z1, ze = _draw_leaf(mu, sig, a, b, c, d, uniform(key, i, 0), uniform(key, i, 1))
                z2 = min(max(z1 + ze, 0.0), L)
                if prune and (z < min(z1, z2) - margin or z > max(z1, z2) + margin):
                    continue
                out_idx[count] = i0 + i
                out_z1[count] = z1
                out_ze[count] = z2 - z1
                count += 1
            continue
        am = 0.5 * (a + b)
        cm = 0.5 * (c + d)
        pa = 0.5  # z1 is uniform: each half of [a, b] is equally likely
        if sig > 0.0:
            fc = _ze_cdf(mu, sig, c)
            fm = _ze_cdf(mu, sig, cm)
            fd = _ze_cdf(mu, sig, d)
            pc = (fm - fc) / (fd - fc) if fd > fc else 0.5
        else:
            pc = 0.5
        p[0] = pa * pc
        p[1] = (1 - pa) * pc
        p[2] = pa * (1 - pc)
        p[3] = (1 - pa) * (1 - pc)
        key = hash_u64(node_seed, nid, STREAM_TREE + 1)
        counts[:] = 0
        for i in range(n):  # multinomial(n; p) as n categorical draws
            u = uniform(key, i, 0)
            q = 0
            acc = p[0]
            while q < 3 and u >= acc:
                q += 1
                acc += p[q]
            counts[q] += 1
        start = i0
        starts = np.empty(4, np.int64)
        for q in range(4):
            starts[q] = start
            start += counts[q]
        for q in range(3, -1, -1):  # push in reverse: quadrant 0 pops first
            if counts[q] == 0:
                continue
            s_id[top] = nid * np.uint64(4) + np.uint64(q)
            s_dep[top] = dep + 1
            s_i0[top] = starts[q]
            s_n[top] = counts[q]
            s_box[top, 0] = a if (q == 0 or q == 2) else am
            s_box[top, 1] = am if (q == 0 or q == 2) else b
            s_box[top, 2] = c if q < 2 else cm
            s_box[top, 3] = cm if q < 2 else d
            top += 1
    return count


@njit(cache=True)
def active_hairs(L, n_hairs, mu, sig, node_seed, z, margin, out_idx, out_z1, out_ze):
    """Algorithm 3: hairs of one ply active at z (index, z1, ze = z2 - z1); returns how many."""
    return _traverse(L, n_hairs, mu, sig, node_seed, z, margin, runtime_value(True), out_idx, out_z1, out_ze)


@njit(cache=True)
def all_hairs(L, n_hairs, mu, sig, node_seed):
    """Every hair of one ply: (z1, ze) arrays indexed by hair index (the hybrid pre-generation)."""
    idx = np.empty(max(n_hairs, 1), np.int64)
    z1 = np.empty(max(n_hairs, 1))
    ze = np.empty(max(n_hairs, 1))
    n = _traverse(L, n_hairs, mu, sig, node_seed, 0.0, 0.0, runtime_value(False), idx, z1, ze)
    o1 = np.empty(n)
    oe = np.empty(n)
    for i in range(n):
        o1[idx[i]] = z1[i]
        oe[idx[i]] = ze[i]
    return o1, oe
