"""Weave and knit generators (stages/ingest/weave.py, woven.py, knit.py, pipeline/generators.py).

References: closed-form float lengths of twill n/m (warp over n, under m), satin n (over n-1,
binding points never adjacent), basket n; woven crossings separated in z by exactly
crimp (r_warp + r_weft) (touching yarns at crimp 1) and a brute-force minimum distance between
warp and weft centrelines; knit courses open/closed as designed, finite, and interlocking: in
projection course i+1 crosses each loop of course i under its legs and over its head (knit) or
the reverse (purl), with the centres >= 2r apart in z at those crossings.
"""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from pipeline.errors import LoomError
from pipeline.generators import generate
from stages.core.curves import woven
from stages.ingest import knit, weave


@pytest.mark.parametrize("n,m", [(1, 1), (2, 1), (2, 2), (3, 1), (1, 3)])
def test_twill_float_lengths(n, m):
    over = weave.twill(n, m, 2 * (n + m), 3 * (n + m))
    for row in over:
        assert weave.float_lengths(row, True) == [n] * 3
        assert weave.float_lengths(row, False) == [m] * 3
    # the diagonal: end e+1 is end e shifted by one pick
    assert np.array_equal(over[1], np.roll(over[0], 1))


@pytest.mark.parametrize("n", [5, 7, 8, 10])
def test_satin_floats_and_binding_points(n):
    for step in weave.satin_steps(n):
        over = weave.satin(n, n, 2 * n, step)
        binds = []
        for row in over:
            assert weave.float_lengths(row, True) == [n - 1] * 2
            binds.append(int(np.argmin(row)))
        binds = np.array(binds)
        # every pick bound once per repeat; neighbouring ends never bound on neighbouring picks
        assert sorted(binds) == list(range(n))
        moves = np.diff(binds) % n
        assert not np.isin(moves, [0, 1, n - 1]).any()


@pytest.mark.parametrize("n", [4, 6])
def test_satin_without_valid_step_is_refused(n):
    with pytest.raises(ValueError, match="no valid step"):
        weave.satin(n, 8, 8)
    with pytest.raises(LoomError, match="fabric.generator"):
        generate({"kind": "woven", "pattern": "satin", "n": n})


def test_plain_and_basket():
    assert weave.plain(4, 4).astype(int).tolist() == [[1, 0, 1, 0], [0, 1, 0, 1]] * 2
    over = weave.basket(3, 12, 12)
    for row in over:
        assert weave.float_lengths(row, True) == [3, 3] and weave.float_lengths(row, False) == [3, 3]
    assert np.array_equal(weave.basket(1, 6, 6), weave.plain(6, 6))


@pytest.mark.parametrize("pattern,extra", [("plain", {}), ("twill", {"n": 2, "m": 1}), ("satin", {"n": 5}),
                                           ("basket", {"n": 2})])
def test_woven_crossings_are_two_radii_apart(pattern, extra):
    s, r, sp = 6, 0.02, 0.1
    gen = {"kind": "woven", "pattern": pattern, "ends": 7, "picks": 5, "spacing": sp, "samples_per_cell": s, **extra}
    cs = generate(gen, yarn_radius=r)
    over = cs.notes["interlacement"]
    E, P = over.shape
    assert cs.group == ["warp"] * E + ["weft"] * P and not any(cs.closed)
    for e in range(E):
        for p in range(P):
            a = cs.points[e][woven.crossing_index(s, p)]
            b = cs.points[E + p][woven.crossing_index(s, e)]
            assert np.allclose(a[:2], b[:2])                     # the same (x, y): the crossing
            assert a[2] - b[2] == pytest.approx(2 * r if over[e, p] else -2 * r)
    for p in cs.points:
        assert np.linalg.norm(np.diff(p, axis=0), axis=1).min() > 0   # no repeated points
    # brute force: densest sampling of the centrelines keeps warp and weft >= 1.9 r apart
    dense = generate({**gen, "samples_per_cell": 64}, yarn_radius=r)
    warp = np.vstack(dense.points[:E])
    weft = np.vstack(dense.points[E:])
    d, _ = cKDTree(weft).query(warp)
    assert d.min() >= 1.9 * r, d.min() / r


def test_woven_crimp_and_two_radii():
    over = weave.twill(2, 2, 4, 4)
    warp, weft = woven.woven_curves(over, 0.1, 0.12, 0.02, 0.03, crimp=0.5, samples_per_cell=4)
    i = woven.crossing_index(4, 1)
    assert warp[0, i, 2] == pytest.approx(0.5 * 0.02 * (1 if over[0, 1] else -1))
    assert weft[1, woven.crossing_index(4, 0), 2] == pytest.approx(0.5 * 0.03 * (-1 if over[0, 1] else 1))
    assert np.allclose(np.diff(weft[0, :, 1]), 0) and np.allclose(np.diff(warp[0, :, 0]), 0)
    assert warp[0, -1, 1] - warp[0, 0, 1] == pytest.approx(4 * 0.12)  # half a cell beyond each end


def _crossings(A, B):
    """Brute-force xy-projection crossings of polylines A and B: (index in A, za, zb)."""
    out = []
    for i in range(len(A) - 1):
        p, r = A[i, :2], A[i + 1, :2] - A[i, :2]
        q, s = B[:-1, :2], B[1:, :2] - B[:-1, :2]
        den = r[0] * s[:, 1] - r[1] * s[:, 0]
        with np.errstate(all="ignore"):
            t = ((q[:, 0] - p[0]) * s[:, 1] - (q[:, 1] - p[1]) * s[:, 0]) / den
            u = ((q[:, 0] - p[0]) * r[1] - (q[:, 1] - p[1]) * r[0]) / den
        for k in np.nonzero((t >= 0) & (t < 1) & (u >= 0) & (u < 1))[0]:
            out.append((i, A[i, 2] + t[k] * (A[i + 1, 2] - A[i, 2]), B[k, 2] + u[k] * (B[k + 1, 2] - B[k, 2])))
    return out


@pytest.mark.parametrize("pattern", knit.PATTERNS)
def test_knit_courses_interlock(pattern):
    W, C, w, h, s = 5, 4, 1.0, 0.8, 32
    r = knit.default_radius(w, h)
    curves, closed = knit.knit_curves(pattern, W, C, w, h, r, s)
    assert curves.shape == (C, W * s + 1, 3) and not closed.any() and np.isfinite(curves).all()
    k = knit.stitch_types(pattern, W, C)
    for i in range(C - 1):
        for j in range(1, W - 1):
            loop = curves[i][j * s:(j + 1) * s + 1]
            new = curves[i + 1][(j - 1) * s + s // 2:(j + 1) * s + s // 2 + 1]
            xs = _crossings(new, loop)
            assert len(xs) == 4, (i, j, len(xs))
            sign = np.array([np.sign(za - zb) for _, za, zb in sorted(xs)])
            # knit (k = +1) of course i+1: under, over, over, under the loop of course i
            assert sign.tolist() == (k[i + 1, j] * np.array([-1, 1, 1, -1])).tolist(), (i, j, sign)
            gaps = [abs(za - zb) for _, za, zb in xs]
            assert min(gaps) >= 2 * r * 0.99
        if i >= 1:  # courses two apart do not meet, even in projection
            assert not _crossings(curves[i + 1], curves[i - 1])


@pytest.mark.parametrize("pattern", knit.PATTERNS)
def test_knit_no_gross_interpenetration(pattern):
    """Brute force: minimum distance between centrelines of different courses (dense sampling).
    Measured with this model at the default radius: >= 1.43 r (stockinette 1.43, garter 1.63,
    rib 1.43); centres at 2r would just touch."""
    r = knit.default_radius(1.0, 0.8)
    curves, _ = knit.knit_curves(pattern, 5, 4, 1.0, 0.8, r, 64)
    dmin = min(cKDTree(curves[b]).query(curves[a])[0].min() for a in range(4) for b in range(a + 1, 4))
    assert dmin >= 1.4 * r, dmin / r


def test_knit_tube_is_closed_and_generator_wraps():
    curves, closed = knit.knit_curves("rib1x1", 6, 3, 1.0, 0.8, 0.05, 16, tube=True)
    assert closed.all() and curves.shape == (3, 96, 3) and np.isfinite(curves).all()
    # the closing segment (last -> first point) is as short as an ordinary one
    steps = np.linalg.norm(np.diff(curves[0], axis=0), axis=1)
    assert 0 < np.linalg.norm(curves[0][0] - curves[0][-1]) <= 1.5 * steps.max()
    cs = generate({"kind": "knit", "pattern": "garter", "ends": 4, "picks": 3, "spacing": 0.2})
    assert cs.group == ["knit"] * 3 and cs.closed == [False] * 3 and cs.curve_type == "catmull-rom"
    assert cs.notes["spacing"] == (0.2, pytest.approx(0.16))
    for p in cs.points:
        assert np.isfinite(p).all() and np.linalg.norm(np.diff(p, axis=0), axis=1).min() > 0


@pytest.mark.parametrize("gen,words", [
    ({"kind": "woven", "pattern": "garter"}, "not a woven pattern"),
    ({"kind": "knit", "pattern": "twill"}, "not a knit pattern"),
    ({"kind": "felt", "pattern": "plain"}, "expected 'woven' or 'knit'"),
    ({"kind": "woven", "pattern": "plain", "samples_per_cell": 1}, "samples_per_cell"),
    ({"kind": "woven", "pattern": "satin", "n": 5, "step": 1}, "step 1 is not valid"),
])
def test_generator_errors(gen, words):
    with pytest.raises(LoomError) as e:
        generate(gen, yarn_radius=0.01)
    assert str(e.value).startswith("fabric.generator: ") and words in str(e.value)


@pytest.mark.parametrize("kind,pattern", [("woven", "twill"), ("knit", "stockinette")])
def test_pleats_fold_the_flat_fabric_by_their_sine(kind, pattern):
    """``pleats = {count, depth}``: every control point is the flat fabric's, lifted by depth/2 sin(2 pi count
    (x - x0) / width) over the curves' x extent (x and y unchanged); the lift spans the depth."""
    gen = {"kind": kind, "pattern": pattern, "ends": 8, "picks": 6, "spacing": 0.2}
    flat, folded = generate(dict(gen)), generate({**gen, "pleats": {"count": 3, "depth": 0.5}})
    P, Q = np.concatenate(flat.points), np.concatenate(folded.points)
    x0, width = P[:, 0].min(), P[:, 0].max() - P[:, 0].min()
    lift = 0.25 * np.sin(2.0 * np.pi * 3 * (P[:, 0] - x0) / width)
    assert np.array_equal(Q[:, :2], P[:, :2]) and np.allclose(Q[:, 2], P[:, 2] + lift, atol=1e-12)
    assert lift.max() - lift.min() > 0.49
