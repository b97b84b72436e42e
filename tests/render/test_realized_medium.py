"""The realized-fibre density source (stages/render/media/realized_medium.py), called directly on random,
overlapping fibres.

References: a brute-force scan of every capsule (segment a-b of a fibre, radius the mean of its two point
radii: the BVH's convention) for the point's covering fibre, the lowest fibre index winning; the yarn tables
the medium was given (density, albedo, roughness) and the segment's own direction for ``medium_lookup``;
the fibres' own segments for ``fiber_capsules``, and a majorant grid built from them bounding every lookup.
"""
import numpy as np
import pytest
from numba import njit

from stages.core.geometry.bvh import build_fiber_bvh
from stages.render.media.medium import medium_lookup
from stages.render.media.realized_medium import RealizedMedium, covering_segment, fiber_capsules
from stages.render.media.tracking import majorants_from_capsules, majorants_from_prims


def _fibres(seed=0, F=40):
    """Random-walk polylines (4-9 points, steps ~0.15) in the unit box with radii 0.02-0.06: they overlap."""
    rng = np.random.default_rng(seed)
    pts, rad, off = [], [], [0]
    for _f in range(F):
        n = int(rng.integers(4, 10))
        p = rng.uniform(0.1, 0.9, 3) + np.cumsum(rng.normal(0, 0.09, (n, 3)), axis=0)
        pts.append(p)
        rad.append(rng.uniform(0.02, 0.06, n))
        off.append(off[-1] + n)
    return np.concatenate(pts), np.concatenate(rad), np.array(off, np.int64)


@pytest.fixture(scope="module")
def medium():
    P, Rr, O = _fibres()
    bvh, _ = build_fiber_bvh(P, O, Rr)
    F = len(O) - 1
    yarn = (np.arange(F) % 3).astype(np.int32)
    med = RealizedMedium(bvh, yarn, np.array([100.0, 250.0, 40.0]),
                         np.array([[0.9, 0.8, 0.7], [0.2, 0.4, 0.6], [0.5, 0.5, 0.1]]), np.array([0.3, 0.6, 1.0]),
                         np.zeros(0, np.int64))
    return med, P, Rr, O


def _brute_segments(P, Rr, O):
    """(a, b, r, fibre) of every segment in fibre order (fibre f's segments are consecutive)."""
    i = np.concatenate([np.arange(O[f], O[f + 1] - 1) for f in range(len(O) - 1)])
    f = np.concatenate([np.full(O[k + 1] - O[k] - 1, k) for k in range(len(O) - 1)])
    return P[i], P[i + 1], 0.5 * (Rr[i] + Rr[i + 1]), f


def _inside(a, b, r, x):
    ab = b - a
    t = np.clip(((x - a) * ab).sum(axis=1) / (ab * ab).sum(axis=1), 0.0, 1.0)
    d = x - a - t[:, None] * ab
    return (d * d).sum(axis=1) < r * r


def _points(P, n, seed):
    """Half uniform over the fibres' box, half near the fibre vertices (most inside, many in overlaps)."""
    rng = np.random.default_rng(seed)
    lo, hi = P.min(axis=0) - 0.05, P.max(axis=0) + 0.05
    return np.concatenate([rng.uniform(lo, hi, (n // 2, 3)),
                           P[rng.integers(0, len(P), n - n // 2)] + rng.normal(0, 0.03, (n - n // 2, 3))])


def test_covering_segment_is_the_lowest_covering_fibre(medium):
    """Reference: brute force over all capsules at 4000 points: -1 where none covers; otherwise the
    returned segment is the lowest-index covering segment of the lowest-index covering fibre (so the
    answer does not depend on how the BVH orders its leaves), and with that fibre skipped, the same
    of the other covering fibres."""
    med, P, Rr, O = medium
    a, b, r, fib = _brute_segments(P, Rr, O)
    X = _points(P, 4000, 1)
    n_multi = 0
    for x in X:
        cov = _inside(a, b, r, x[None, :])
        s = covering_segment(med.bvh, *x)
        if not cov.any():
            assert s == -1
            continue
        n_multi += len(set(fib[cov])) > 1
        assert s >= 0 and cov[s], (x, s)
        f = fib[cov].min()
        assert med.bvh.seg_fiber[s] == f
        assert s == np.flatnonzero(cov & (fib == f)).min()
        # skipping that fibre (a ray leaving it): the next covering fibre, or none
        s2 = covering_segment(med.bvh, *x, f)
        rest = cov & (fib != f)
        if not rest.any():
            assert s2 == -1
            continue
        f2 = fib[rest].min()
        assert med.bvh.seg_fiber[s2] == f2 and s2 == np.flatnonzero(rest & (fib == f2)).min()
    assert n_multi > 100  # overlaps were exercised


@njit
def _lookup(med, X):
    out = np.empty((X.shape[0], 10))
    for k in range(X.shape[0]):
        r = medium_lookup(med, X[k, 0], X[k, 1], X[k, 2], -1)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = r.den, r.tx, r.ty, r.tz
        out[k, 4], out[k, 5], out[k, 6], out[k, 7] = r.albedo_r, r.albedo_g, r.albedo_b, r.roughness
        out[k, 8], out[k, 9] = r.yarn, r.fibre
    return out


def test_medium_lookup_returns_the_yarn_and_the_segment_tangent(medium):
    """Reference: at 4000 points, medium_lookup (through the source's overload) gives density, albedo and
    roughness of the covering fibre's yarn and the unit direction of the covering segment; density 0
    outside every capsule (brute force)."""
    med, P, Rr, O = medium
    a, b, r, fib = _brute_segments(P, Rr, O)
    X = _points(P, 4000, 2)
    out = _lookup(med, X)
    for x, o in zip(X, out):
        cov = _inside(a, b, r, x[None, :])
        if not cov.any():
            assert o[0] == 0.0
            continue
        f = fib[cov].min()
        c = med.fiber_yarn[f]
        assert o[0] == med.yarn_density[c]
        np.testing.assert_array_equal(o[4:7], med.yarn_albedo[c])
        assert o[7] == med.yarn_roughness[c]
        assert o[8] == c and o[9] == f  # the covering fibre's yarn and the fibre itself
        cand = np.flatnonzero(cov & (fib == f))
        dirs = (b[cand] - a[cand]) / np.linalg.norm(b[cand] - a[cand], axis=1)[:, None]
        assert np.min(np.linalg.norm(dirs - o[1:4], axis=1)) < 1e-12


def test_majorants_read_from_the_packed_capsules_are_the_listed_ones(medium):
    """Reference: majorants_from_capsules over fiber_capsules' list. Reading the BVH's packed capsules in
    place (leaf order, the fibre cache's majorant) gives the same grid, bit for bit."""
    med, P, Rr, O = medium
    ca, cb, cr, bound = fiber_capsules(med)
    lo, hi = P.min(axis=0) - 0.1, P.max(axis=0) + 0.1
    for res in (np.array([7, 6, 5]), np.array([31, 29, 11])):
        want = majorants_from_capsules(ca, cb, cr, bound, lo, hi, res)
        got = majorants_from_prims(med.bvh.prims, med.bvh.seg_fiber, med.fiber_yarn, med.yarn_density, lo, hi, res)
        assert np.array_equal(got, want) and (want > 0).mean() > 0.1


def test_fiber_capsules_bound_every_fibre(medium):
    """Reference: fiber_capsules lists the fibres' own segments (end points, mean radius) with the yarn's
    density as bound; a majorant grid built from them is >= the density medium_lookup gives at 4000 points."""
    med, P, Rr, O = medium
    a, b, r, fib = _brute_segments(P, Rr, O)
    ca, cb, cr, bound = fiber_capsules(med)
    order = np.lexsort((med.bvh.seg_a,))
    np.testing.assert_array_equal(ca[order], a)
    np.testing.assert_array_equal(cb[order], b)
    np.testing.assert_allclose(cr[order], r, rtol=1e-15)
    np.testing.assert_array_equal(bound[order], med.yarn_density[med.fiber_yarn[fib]])
    lo, hi = P.min(axis=0) - 0.1, P.max(axis=0) + 0.1
    res = np.array([7, 6, 5])
    mu = majorants_from_capsules(ca, cb, cr, bound, lo, hi, res)
    X = _points(P, 4000, 3)
    den = _lookup(med, X)[:, 0]
    ijk = np.floor((X - lo) / (hi - lo) * res).astype(int)
    assert (den > 0).sum() > 1000
    assert np.all(mu[ijk[:, 2], ijk[:, 1], ijk[:, 0]] >= den)
