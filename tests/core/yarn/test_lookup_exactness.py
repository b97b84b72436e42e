"""Exactness of the realization-minimizing lookups (seed 000 §4) against brute force on the realized fibres.

Swatch: a 2 x 2 plain weave of cotton2 yarns (all three fibre kinds), realized at spacing 0.001.
Reference: ``stages.procedural.realized_reference`` -- the distance from every point to every realized
segment of its grid cell (chains of capsules), the same covering rule (first fibre in the order
yarn, ply, regular/loop before hair, index).

Tolerance. The realized polylines join points that lie exactly on the fibre centre curves (up to
float32 rounding), so a polyline strays from its curve by at most the sagitta of a chord,
kappa l^2 / 8 for a chord of length l on a curve of curvature kappa. The realization measures it
(``max_chord_error``: l theta / 8 at every vertex, theta the turning angle between its segments,
i.e. kappa l^2 / 8 with kappa = theta / l). tol = 2 x max_chord_error (margin for the discrete
curvature estimate) + float32 rounding of the vertices (4 ulp of the largest coordinate). Points
within tol of any fibre surface, and points where a fibre's regular and loop pieces are within tol
of each other (a kind tie at a piece joint), are not compared; all others must agree exactly in
inside/outside, yarn and kind, and in direction to 1 degree or, where the realization turns more
sharply (the demo's finer fibres), to 0.6 x its largest turn (chord vs tangent: at most theta / 2,
reported by the realization as ``max_turn_rad``).
"""
import numpy as np
import pytest

from pipeline.artifacts import Artifact
from pipeline.runners.realize import run_realize
from pipeline.runners.tables import build
from stages.core.yarn.lookup import lookup_points
from stages.procedural.realized_reference import build_segment_grid, query_realized, segment_fiber
from tests.helpers import DATA, EXACTNESS_SWATCH as SCENE, closed_ring_scene, seam_points


@pytest.fixture(scope="module")
def swatch(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("exact")
    (d / "s.toml").write_text(SCENE)
    assert main(["ingest", str(d / "s.toml"), "-o", str(d / "yarns.zarr")]) == 0
    run_realize(d / "yarns.zarr", d / "fibers.zarr", seed=3, spacing=0.001)
    fib = Artifact(d / "fibers.zarr", kind="fibers")
    cv, tab, info, _, _ = build(d / "yarns.zarr", seed=3, hair_mode="hybrid")
    cv2, tab_free, _, _, _ = build(d / "yarns.zarr", seed=3, hair_mode="free")
    assert not info["folded"].any()
    return d, fib, cv, {"hybrid": tab, "free": tab_free}


def _points(fib, n_uniform=30000, n_near=90000, seed=0):
    pts = np.asarray(fib["points"], np.float64)
    rng = np.random.default_rng(seed)
    lo, hi = pts.min(0) - 0.01, pts.max(0) + 0.01
    rf = float(np.max(fib["point_radius"]))
    q1 = rng.uniform(lo, hi, (n_uniform, 3))
    q2 = pts[rng.integers(0, len(pts), n_near)] + rng.normal(0.0, 1.5 * rf, (n_near, 3))
    return np.concatenate([q1, q2])


def _assert_exact(fib, cv, tab, Q, min_inside, min_clear=0.95):
    """lookup_points(Q) against the brute-force reference on the realized fibres (module doc);
    at least min_clear of the points lie clear of the tolerance band and take part."""
    pts32 = np.asarray(fib["points"])
    rad = np.asarray(fib["point_radius"])
    off = np.asarray(fib["fiber_offsets"])
    kinds = np.asarray(fib["fiber_kind"])
    chord = fib.summary["max_chord_error"]
    tol = 2.0 * chord + 4 * np.finfo(np.float32).eps * float(np.abs(pts32).max())
    assert tol < 0.05 * float(rad.max())  # the band is thin next to the fibre radius
    lo, cell, dims, start, items = build_segment_grid(pts32, off, rad, tol)
    ref = query_realized(pts32, rad, segment_fiber(off), np.asarray(fib["fiber_yarn"]), np.asarray(fib["fiber_ply"]),
                         kinds, np.asarray(fib["fiber_index"]), lo, cell, dims, start, items, Q, tol)
    got = lookup_points(cv, tab, Q)
    clear = (ref.surface_gap > tol) & ~ref.kind_tie
    assert clear.mean() > min_clear
    inside_ref = ref.inside[clear]
    assert inside_ref.sum() > min_inside  # many points inside fibres take part
    assert np.array_equal(got.inside[clear], inside_ref)
    both = clear & ref.inside
    assert np.array_equal(got.yarn[both], ref.yarn[both])
    assert np.array_equal(got.kind[both], ref.kind[both])
    cosang = np.einsum("ij,ij->i", got.direction[both], ref.direction[both])
    # a chord leaves its arc's tangent by at most half the turn at its ends (max_turn_rad, 20 % margin)
    max_angle = max(1.0, 0.6 * np.degrees(fib.summary["max_turn_rad"]))
    assert np.degrees(np.arccos(np.clip(cosang, -1, 1))).max() < max_angle
    assert np.all(got.yarn[~got.inside] == -1) and np.all(got.kind[~got.inside] == 0)
    np.testing.assert_allclose(np.linalg.norm(got.direction[got.inside], axis=1), 1.0, rtol=1e-9)
    return got, both


def test_lookup_equals_brute_force_on_realized_fibres(swatch):
    d, fib, cv, tabs = swatch
    assert set(np.unique(np.asarray(fib["fiber_kind"]))) == {1, 2, 3}
    Q = _points(fib)
    assert len(Q) >= 100_000
    got, both = _assert_exact(fib, cv, tabs["hybrid"], Q, 5000)
    assert set(np.unique(got.kind[both])) == {1, 2, 3}


@pytest.mark.slow
def test_closed_yarn_seam_is_exact(tmp_path):
    """A closed yarn (a gently waved ring, BCC negative count): its fibres run from s = 0 to L and
    meet at the seam without joining; points around the seam are covered by the pieces at both
    ends. Same brute-force reference and tolerance as above, points concentrated at the seam."""
    from pipeline.cli import main

    ring, scene = closed_ring_scene(tmp_path)
    (tmp_path / "s.toml").write_text(scene)
    assert main(["ingest", str(tmp_path / "s.toml"), "-o", str(tmp_path / "yarns.zarr")]) == 0
    run_realize(tmp_path / "yarns.zarr", tmp_path / "fibers.zarr", seed=3, spacing=0.001)
    fib = Artifact(tmp_path / "fibers.zarr", kind="fibers")
    cv, tab, info, _, _ = build(tmp_path / "yarns.zarr", seed=3, hair_mode="hybrid")
    assert bool(cv.closed[0]) and not info["folded"].any()
    Q = seam_points(fib, ring, 60000, 20000)
    _assert_exact(fib, cv, tab, Q, 10000)


def test_hybrid_and_realization_free_hairs_agree(swatch):
    d, fib, cv, tabs = swatch
    tab, tab_free = tabs["hybrid"], tabs["free"]
    assert len(tab_free.hair_z1) == 0 and len(tab.hair_z1) > 0  # the free mode stores no hair data
    Q = _points(fib, 5000, 25000, seed=1)
    a = lookup_points(cv, tab, Q)
    b = lookup_points(cv, tab_free, Q)
    assert (a.kind == 3).sum() > 100
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def _demo_swatch(d):
    from pipeline.cli import main

    (d / "s.toml").write_text((DATA / "scenes" / "demo.toml").read_text())
    assert main(["ingest", str(d / "s.toml"), "-o", str(d / "yarns.zarr")]) == 0
    return d / "yarns.zarr"


def test_demo_swatch_tables_are_exact(tmp_path):
    """The flagship picture is the exact method's (issue 21 item 5): the demo's yarns bend gently
    enough that the yarn-space map does not fold within their fibre extent (curvature x extent
    below the tables' fold cap), so its tables guarantee exact lookups."""
    from stages.procedural.tables import FOLD_CAP

    _, _, info, _, _ = build(_demo_swatch(tmp_path), seed=3, hair_mode="hybrid", derive=False)
    assert not info["folded"].any()
    assert (info["curvature_max"] * info["extent"]).max() < FOLD_CAP


@pytest.mark.slow
def test_demo_swatch_lookups_equal_brute_force(tmp_path):
    """The same exactness check as on the gentle swatch, on the demo's (denser) voile: its fibres
    are thinner and packed closer, so more of the points near fibres fall in the tolerance band."""
    yarns = _demo_swatch(tmp_path)
    run_realize(yarns, tmp_path / "fibers.zarr", seed=3, spacing=0.0005)
    fib = Artifact(tmp_path / "fibers.zarr", kind="fibers")
    cv, tab, info, _, _ = build(yarns, seed=3, hair_mode="hybrid")
    assert not info["folded"].any()
    _assert_exact(fib, cv, tab, _points(fib, 30000, 90000), 20000, min_clear=0.8)
