"""The SIMD wide-node box tests (``stages.core.geometry.box4``) against the scalar slab test they replace.

Reference: the slab test written per child in numpy float64 with the same operations in the same
order (each float32 bound widened, minus the origin, times the reciprocal direction; a plane's
distance replaces the running near / far distance only when strictly nearer / farther), so the SIMD
results must be the same bits, including misses (inf), empty slots (lo = +inf, hi = -inf), axis-
parallel rays (reciprocal 1e300, ``slab.safe_inverse``) and points exactly on a bound.
"""
import numpy as np
import pytest
from numba import njit

from stages.core.geometry.box4 import box4_contains, box4_enter
from stages.core.geometry.slab import safe_inverse
from stages.core.geometry.wide_walk import direction_signs


def _boxes(rng, m=64):
    lo = rng.random((m, 3, 4)).astype(np.float32)
    hi = lo + (rng.random((m, 3, 4)) * 0.6).astype(np.float32)
    box = np.concatenate([lo.reshape(m, 12), hi.reshape(m, 12)], 1)
    for q in range(4):                                   # empty slots, as collapse_wide writes them
        rows = np.arange(q, m, 9)
        box[rows[:, None], [q, 4 + q, 8 + q]] = np.inf
        box[rows[:, None], [12 + q, 16 + q, 20 + q]] = -np.inf
    return np.ascontiguousarray(box, np.float32)


def _enter_ref(box, w, o, inv, s, tmin, tmax):
    out = np.empty(4)
    for q in range(4):
        tn = (np.float64(box[w, s[0] + q]) - o[0]) * inv[0]
        tf = (np.float64(box[w, 12 - s[0] + q]) - o[0]) * inv[0]
        for k in (1, 2):
            t0 = (np.float64(box[w, 4 * k + s[k] + q]) - o[k]) * inv[k]
            t1 = (np.float64(box[w, 12 + 4 * k - s[k] + q]) - o[k]) * inv[k]
            tn = t0 if t0 > tn else tn
            tf = t1 if t1 < tf else tf
        out[q] = tn if (tf >= tn and tf >= tmin and tn <= tmax) else np.inf
    return out


@njit(cache=True)
def _enter(box, w, o, d, tmin, tmax):
    ix = safe_inverse(d[0])
    iy = safe_inverse(d[1])
    iz = safe_inverse(d[2])
    sx, sy, sz = direction_signs(ix, iy, iz)
    t = box4_enter(box, w, sx, sy, sz, o[0], o[1], o[2], ix, iy, iz, tmin, tmax)
    return np.array([t[0], t[1], t[2], t[3]]), np.array([ix, iy, iz]), np.array([sx, sy, sz])


@njit(cache=True)
def _contains(box, w, p):
    return box4_contains(box, w, p[0], p[1], p[2])


@pytest.mark.parametrize("seed", [0, 1])
def test_box4_enter_is_the_scalar_slab_test_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    box = _boxes(rng)
    entered = 0
    for it in range(4000):
        w = int(rng.integers(len(box)))
        o = rng.random(3) * 1.4 - 0.2
        target = box[w, :12].reshape(3, 4)[:, it % 4].astype(np.float64) + rng.random(3) * 0.3
        d = target - o if it % 2 and np.all(np.isfinite(target)) else rng.normal(size=3)  # (not at an empty slot)
        if it % 5 == 0:
            d[rng.integers(3)] = 0.0 if it % 10 else -0.0   # axis-parallel
        tmin, tmax = rng.random() * 0.3, 0.5 + rng.random() * 3.0
        got, inv, s = _enter(box, w, o, d, tmin, tmax)
        want = _enter_ref(box, w, o, inv, s, tmin, tmax)
        assert np.array_equal(got.view(np.int64), want.view(np.int64)), (it, got, want)
        entered += int(np.isfinite(got).sum())
    assert entered > 1000          # the rays aimed at boxes do enter them: both branches are exercised


@pytest.mark.parametrize("seed", [0, 1])
def test_box4_contains_is_the_scalar_test(seed):
    rng = np.random.default_rng(seed)
    box = _boxes(rng)
    held = 0
    for it in range(4000):
        w = int(rng.integers(len(box)))
        p = rng.random(3) * 1.4 - 0.1
        if it % 2:                                       # in (or near) a chosen child's box
            q = it % 4
            lo, hi = (box[w, 4 * np.arange(3) + q].astype(np.float64),
                      box[w, 12 + 4 * np.arange(3) + q].astype(np.float64))
            if np.all(np.isfinite(lo)):
                p = lo + (hi - lo) * (rng.random(3) * 1.2 - 0.1)
        if it % 3 == 0:                                  # exactly on a bound: bounds are inside
            q, k = int(rng.integers(4)), int(rng.integers(3))
            p[k] = float(box[w, 4 * k + q] if it % 2 else box[w, 12 + 4 * k + q])
        want = sum(1 << q for q in range(4)
                   if all(np.float64(box[w, 4 * k + q]) <= p[k] <= np.float64(box[w, 12 + 4 * k + q])
                          for k in range(3)))
        assert _contains(box, w, p) == want, it
        held += want != 0
    assert held > 500
