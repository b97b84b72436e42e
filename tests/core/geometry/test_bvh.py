"""Ray-capsule intersection (closed forms) and the SAH BVH (brute force over all segments)."""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.geometry.bvh import build_fiber_bvh, intersect, intersect_brute, occluded
from stages.core.geometry.capsule import capsule_intersect, capsule_normal
from stages.core.geometry.wide_walk import LEAF_CODE


def random_fibres(seed, n_fibres=40, n_points=16, box=1.0, radius=0.02):
    """Random-walk polylines (some points repeated to exercise zero-length segments)."""
    rng = np.random.default_rng(seed)
    pts, offs, rad = [], [0], []
    for f in range(n_fibres):
        p = rng.uniform(-box, box, 3)
        step = rng.normal(size=3)
        for k in range(n_points):
            pts.append(p.copy())
            rad.append(radius * rng.uniform(0.5, 1.5))
            step = 0.7 * step + 0.3 * rng.normal(size=3)
            p = p + 0.08 * step / np.linalg.norm(step) * (0.0 if (f == 3 and k == 5) else 1.0)
        offs.append(len(pts))
    return np.asarray(pts), np.asarray(offs), np.asarray(rad)


@njit
def _queries(bvh, O, D, tmin, ign_f, ign_s, window):
    n = O.shape[0]
    out = np.empty((n, 5))
    for k in range(n):
        t, s = intersect(bvh, O[k, 0], O[k, 1], O[k, 2], D[k, 0], D[k, 1], D[k, 2],
                         tmin, np.inf, ign_f[k], ign_s[k], window)
        tb, sb = intersect_brute(bvh, O[k, 0], O[k, 1], O[k, 2], D[k, 0], D[k, 1], D[k, 2],
                                 tmin, np.inf, ign_f[k], ign_s[k], window)
        tmax = 0.5 * tb if tb < np.inf else 10.0
        occ_half = occluded(bvh, O[k, 0], O[k, 1], O[k, 2], D[k, 0], D[k, 1], D[k, 2],
                            tmin, tmax, ign_f[k], ign_s[k], window)
        out[k, 0] = t
        out[k, 1] = s
        out[k, 2] = tb
        out[k, 3] = sb
        out[k, 4] = 1.0 if occ_half else 0.0
    return out


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("seed", [1, 2])
def test_bvh_matches_brute_force(seed):
    """Reference: brute force over all segments; identical first hits (t and segment) for random rays
    from outside, rays starting on fibre surfaces (skipping their own chain neighbourhood) and
    grazing rays along segment axes. occluded() agrees with the brute-force hit distance."""
    pts, offs, rad = random_fibres(seed)
    bvh, fso = build_fiber_bvh(pts, offs, rad)
    S = len(bvh.seg_a)
    # the BVH holds every segment once; children lie inside their parents
    assert sorted(bvh.prim.tolist()) == list(range(S))
    for nd in range(len(bvh.node_left)):
        for ch in (bvh.node_left[nd], bvh.node_right[nd]):
            if ch >= 0:
                assert np.all(bvh.node_lo[ch] >= bvh.node_lo[nd]) and np.all(bvh.node_hi[ch] <= bvh.node_hi[nd])
    rng = np.random.default_rng(seed + 100)
    n = 1500
    # 1. from outside towards the cloud
    O1 = _unit(rng.normal(size=(n, 3))) * 3.0
    D1 = _unit(rng.uniform(-0.8, 0.8, (n, 3)) - O1)
    # 2. from points on fibre surfaces, random directions, own neighbourhood skipped
    s_idx = rng.integers(0, S, n)
    a = pts[bvh.seg_a[s_idx]]
    b = pts[bvh.seg_a[s_idx] + 1]
    u = rng.random(n)[:, None]
    axis_pt = a + u * (b - a)
    nrm = _unit(np.cross(b - a + 1e-9, rng.normal(size=(n, 3))))
    O2 = axis_pt + nrm * bvh.seg_r[s_idx][:, None]
    D2 = _unit(rng.normal(size=(n, 3)))
    # 3. grazing: along the axis of a segment, starting just outside its end sphere
    t_ax = _unit(b - a + 1e-12)
    O3 = a - t_ax * (bvh.seg_r[s_idx][:, None] * 3.0) + nrm * (bvh.seg_r[s_idx][:, None] * rng.uniform(0, 1.2, (n, 1)))
    D3 = t_ax
    O = np.concatenate([O1, O2, O3])
    D = np.concatenate([D1, D2, D3])
    ign_f = np.concatenate([np.full(n, -1), bvh.seg_fiber[s_idx], np.full(n, -1)]).astype(np.int64)
    ign_s = np.concatenate([np.full(n, -1), s_idx, np.full(n, -1)]).astype(np.int64)
    res = _queries(bvh, O, D, 1e-9, ign_f, ign_s, 2)
    hits = np.isfinite(res[:, 2])
    assert hits[:n].mean() > 0.2 and hits[2 * n:].mean() > 0.5   # the test exercises hits
    np.testing.assert_array_equal(res[:, 1], res[:, 3])
    np.testing.assert_array_equal(res[:, 0], res[:, 2])
    # occluded over [tmin, t_hit/2) is false when there is a hit; over [tmin, 10) true iff a hit exists
    assert not np.any(res[hits, 4] > 0)
    np.testing.assert_array_equal(res[~hits, 4], 0.0)


def _wide_leaves(bvh, ref, out):
    """Collect (node, slot, first, count) of every leaf under wide node ``ref``, recursively."""
    for q in range(4):
        c = int(bvh.wide_child[ref, q])
        if c >= 0:
            _wide_leaves(bvh, c, out)
        else:
            code = -1 - c
            out.append((ref, q, code // LEAF_CODE, code % LEAF_CODE))


@pytest.mark.parametrize("seed", [1, 2])
def test_wide_nodes_hold_every_segment_in_outward_rounded_boxes(seed):
    """Contract of the 4-wide tree the queries walk: every segment lies in exactly one leaf; each child
    box (float32) contains the exact float64 bounds of every capsule below it (rounded outward, never
    inward); unused slots are empty boxes (lo > hi, no ray enters them); both arrays start on a 64-byte
    boundary; a wide tree has about a third as many nodes as the binary one."""
    from stages.core.geometry.bvh import segment_bounds

    pts, offs, rad = random_fibres(seed, n_fibres=60)
    bvh, _ = build_fiber_bvh(pts, offs, rad)
    lo, hi = segment_bounds(bvh.points, bvh.seg_a, bvh.seg_r)
    leaves = []
    _wide_leaves(bvh, 0, leaves)
    segs = [int(bvh.prims[j, 7]) for _, _, first, n in leaves for j in range(first, first + n)]
    assert sorted(segs) == list(range(len(bvh.seg_a)))
    box = bvh.wide_box.astype(np.float64)

    def below(ref, q):
        c = int(bvh.wide_child[ref, q])
        if c < 0:
            code = -1 - c
            return [int(bvh.prims[j, 7]) for j in range(code // LEAF_CODE, code // LEAF_CODE + code % LEAF_CODE)]
        return [s for qq in range(4) for s in below(c, qq)]

    checked = 0
    for ref in range(len(box)):
        for q in range(4):
            s = below(ref, q)
            blo = box[ref, [q, 4 + q, 8 + q]]
            bhi = box[ref, [12 + q, 16 + q, 20 + q]]
            if not s:
                assert np.all(blo > bhi)
                continue
            assert np.all(blo <= lo[s].min(axis=0)) and np.all(bhi >= hi[s].max(axis=0))
            checked += 1
    assert checked > len(box)   # the tree is wider than binary
    assert len(bvh.wide_box) < 0.5 * len(bvh.node_left)
    assert bvh.wide_box.ctypes.data % 64 == 0 and bvh.wide_child.ctypes.data % 64 == 0


def test_capsule_closed_forms():
    """Reference: closed-form distances to a cylinder body, an end sphere, and a far-away origin."""
    a = (0.0, 0.0, 0.0)
    b = (1.0, 0.0, 0.0)
    r = 0.1
    # perpendicular ray from above at x = 0.3: hits the body at z = r
    assert capsule_intersect(0.3, 0.0, 5.0, 0.0, 0.0, -1.0, *a, *b, r, 0.0) == pytest.approx(5.0 - r, abs=1e-14)
    # along the axis (grazing, a = 0 in the body quadratic): enters the end sphere at x = -r
    assert capsule_intersect(-3.0, 0.0, 0.0, 1.0, 0.0, 0.0, *a, *b, r, 0.0) == pytest.approx(3.0 - r, abs=1e-14)
    # parallel to the axis at offset h < r: sphere entry at x = -sqrt(r^2 - h^2)
    h = 0.06
    assert capsule_intersect(-3.0, h, 0.0, 1.0, 0.0, 0.0, *a, *b, r, 0.0) == pytest.approx(
        3.0 - math.sqrt(r * r - h * h), abs=1e-13)
    # tangent-grazing miss just outside the body
    assert capsule_intersect(0.5, 0.0, 5.0, 0.0, 1.0, 0.0, *a, *b, r, 0.0) == math.inf
    # far origin 1e6 away: the hit is accurate to 1e-9 relative to the capsule size
    d = np.array([-1.0, 0.2, -0.3])
    d /= np.linalg.norm(d)
    o = np.array([0.5, 0.0, r]) - 1e6 * d
    t = capsule_intersect(*o, *d, *a, *b, r, 0.0)
    p = o + t * d
    dist_axis = math.hypot(p[1], p[2])
    assert dist_axis == pytest.approx(r, abs=1e-9)
    # a ray starting on the surface going outward does not hit its own capsule
    nx, ny, nz, s = capsule_normal(0.4, 0.0, r, *a, *b)
    assert (nx, ny, nz) == pytest.approx((0.0, 0.0, 1.0)) and s == pytest.approx(0.4)
    assert capsule_intersect(0.4, 0.0, r, 0.0, 0.0, 1.0, *a, *b, r, 1e-12) == math.inf


def test_capsule_first_hit_is_the_entry():
    """Contract: from outside, the hit lies on the surface and no point of the ray before it is inside
    the capsule (the early stop at a body hit skips the end spheres: they must not be nearer); a miss
    passes no point inside. Random rays at random capsules, marched at 400 points."""
    rng = np.random.default_rng(11)
    hits = 0
    for _ in range(400):
        a = rng.normal(size=3)
        b = a + rng.normal(size=3) * rng.choice([0.02, 0.3, 1.0])
        r = rng.uniform(0.01, 0.2)
        target = a + rng.uniform(-0.2, 1.2) * (b - a) + rng.normal(size=3) * r
        o = target + rng.normal(size=3)
        d = target - o
        d /= np.linalg.norm(d)

        def dist(p, a=a, b=b):
            ab = b - a
            s = min(max(np.dot(p - a, ab) / np.dot(ab, ab), 0.0), 1.0)
            return np.linalg.norm(p - (a + s * ab))

        if dist(o) <= r:
            continue
        t = capsule_intersect(*o, *d, *a, *b, r, 0.0)
        end = t if t < math.inf else np.linalg.norm(target - o) + 3.0 + np.linalg.norm(b - a)
        march = np.linspace(0.0, end, 400, endpoint=False)
        assert all(dist(o + u * d) > r * (1 - 1e-9) for u in march)
        if t < math.inf:
            hits += 1
            assert dist(o + t * d) == pytest.approx(r, rel=1e-9)
    assert hits > 100


def test_capsule_from_inside_meets_its_way_out():
    """Reference: a ray that starts inside a capsule (a fibre overlapping the one the ray leaves) meets
    it where it leaves: through the body at the radius (closed form), through an end sphere at its
    far root; a ray starting on the surface going inward still passes (it is not inside)."""
    a, b, r = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.1
    # from the axis at x = 0.5 straight up: leaves the body at z = r
    assert capsule_intersect(0.5, 0.0, 0.0, 0.0, 0.0, 1.0, *a, *b, r, 0.0) == pytest.approx(r, abs=1e-14)
    # from (0.5, 0, 0.03) along +x: leaves through the end sphere at b, x = 1 + sqrt(r^2 - 0.03^2)
    assert capsule_intersect(0.5, 0.0, 0.03, 1.0, 0.0, 0.0, *a, *b, r, 0.0) == pytest.approx(
        0.5 + math.sqrt(r * r - 0.03 ** 2), abs=1e-13)
    # random interior points and directions: the exit point lies on the surface, beyond the origin
    rng = np.random.default_rng(3)
    for _ in range(200):
        p = np.array([rng.uniform(-r, 1 + r), *rng.uniform(-r, r, 2)])
        s = min(max(p[0], 0.0), 1.0)
        if np.linalg.norm(p - [s, 0, 0]) >= 0.99 * r:
            continue
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        t = capsule_intersect(*p, *d, *a, *b, r, 0.0)
        q = p + t * d
        sq = min(max(q[0], 0.0), 1.0)
        assert 0.0 < t < 1.0 + 3 * r and np.linalg.norm(q - [sq, 0, 0]) == pytest.approx(r, abs=1e-12)
    # on the surface, heading inward: not inside, so no hit from this capsule's own surface point
    assert capsule_intersect(0.4, 0.0, r, 0.0, 0.0, -1.0, *a, *b, r, 1e-12) == math.inf
