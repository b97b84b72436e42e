"""The lookups' derived frame samples (stages.core.yarn.frame_samples) against their references.

1. Error bound: Eq. 7 under the sampled frames (``frame_at`` + ``eq7``) stays within the measured
   bound eps_c (``yarn_eps``) of Eq. 7 under the exact rotation-minimising frames
   (``stages.core.curves.curve_frame_at``) at random arc lengths and cross-section offsets inside
   the yarn's extent.
2. Foot point: ``foot_point`` (safeguarded Newton on the Hermite axis) against brute force, the
   nearest of 20,000 samples of the same Hermite axis refined by golden-section search.
3. Order: position, normal and binormal are cubic Hermite interpolants of values and derivatives,
   so halving the step divides the measured error by about 16 (fourth order); on a closed ring
   whose frame turns at the holonomy's rate, the bound of 1 holds too.
Scenes: conftest.EXACTNESS_SWATCH (gentle crimp, not folded); a twisted closed ring.
"""
import math

import numpy as np
import pytest

from pipeline.runners.tables import build
from stages.core.curves.frames import curve_frame_at
from stages.core.yarn.frame_samples import eq7, foot_point, frame_at, sample_all
from tests.helpers import EXACTNESS_SWATCH as SCENE


@pytest.fixture(scope="module")
def swatch(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("frames")
    (d / "s.toml").write_text(SCENE)
    assert main(["ingest", str(d / "s.toml"), "-o", str(d / "yarns.zarr")]) == 0
    cv, tab, info, _, _ = build(d / "yarns.zarr", seed=3)
    assert not info["folded"].any()
    return cv, tab


def _axis(tab, c, s):
    lo = tab.fs_at[c]
    hi = lo + tab.fs_n[c]
    return np.array(frame_at(tab.fs_s, tab.fs_frame, lo, hi, lo, s)[1][:3])


def _within_eps(cv, tab):
    rng = np.random.default_rng(1)
    for c in range(len(tab.yarn_type)):
        lo = tab.fs_at[c]
        hi = lo + tab.fs_n[c]
        L, ext, eps = tab.yarn_length[c], tab.yarn_extent[c], tab.yarn_eps[c]
        worst = 0.0
        for s, r, a in zip(rng.uniform(0, L, 400), ext * np.sqrt(rng.uniform(0, 1, 400)),
                           rng.uniform(0, 2 * np.pi, 400)):
            x, y = r * math.cos(a), r * math.sin(a)
            _, f = frame_at(tab.fs_s, tab.fs_frame, lo, hi, lo, s)
            pos, t, n, b = curve_frame_at(cv, c, s)
            worst = max(worst, float(np.linalg.norm(np.array(eq7(f, x, y)) - (pos + x * n + y * b))))
        assert worst <= eps, (c, worst, eps)
        assert worst > 0.05 * eps  # the bound is measured, not a blanket margin


def test_sampled_frames_stay_within_eps(swatch):
    _within_eps(*swatch)


def test_twisted_closed_ring_frames_stay_within_eps(tmp_path):
    """A closed yarn whose frame must turn (holonomy) to close up: the twist rate w enters the
    interpolated normal and binormal (without it the error is 5x larger) and the bound holds."""
    from pipeline.cli import main
    from pipeline.curveset import CurveSet
    from pipeline.io import bcc
    from stages.core.yarn.frame_samples import sample_error

    th = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    ring = np.c_[0.6 * np.cos(th) * (1.0 + 0.2 * np.cos(3.0 * th)), 0.6 * np.sin(th), 0.2 * np.sin(3.0 * th)]
    bcc.write(tmp_path / "ring.bcc", CurveSet(points=[ring], closed=[True], group=["other"],
                                              point_radius=[np.full(len(ring), 0.03)], curve_type="catmull-rom",
                                              source_format="bcc", notes={}))
    (tmp_path / "s.toml").write_text('[scene]\nname = "ring"\n[fabric]\nsource = "file"\n'
                                     f'path = "{tmp_path / "ring.bcc"}"\nradius = 0.03\n'
                                     '[yarns.default]\npreset = "cotton2"\n')
    assert main(["ingest", str(tmp_path / "s.toml"), "-o", str(tmp_path / "yarns.zarr")]) == 0
    cv, tab, _, _, _ = build(tmp_path / "yarns.zarr", seed=3)
    assert bool(cv.closed[0]) and abs(cv.frame_twist[0]) > 1.0
    _within_eps(cv, tab)
    no_twist = tab.fs_frame.copy()
    no_twist[:, 16] = 0.0
    ext = float(tab.yarn_extent[0])
    n = len(tab.fs_s)
    assert sample_error(cv, 0, tab.fs_s, no_twist, ext, 0, n) > 3.0 * sample_error(cv, 0, tab.fs_s, tab.fs_frame,
                                                                                    ext, 0, n)


def test_interpolation_error_is_fourth_order(swatch):
    cv, tab = swatch
    Y = len(tab.yarn_type)
    gaps = np.diff(np.sort(np.concatenate([cv.seg_arclen, cv.frame_s])))
    step = 0.2 * float(np.min(gaps[gaps > 1e-9]))  # well inside every breakpoint interval
    errs = [sample_all(cv, np.full(Y, h), np.asarray(tab.yarn_extent, np.float64))[3] for h in (step, step / 2)]
    ratio = errs[0] / errs[1]
    assert np.all((ratio > 11.0) & (ratio < 22.0)), ratio


def test_foot_point_matches_brute_force(swatch):
    cv, tab = swatch
    rng = np.random.default_rng(2)
    c = 0
    lo = tab.fs_at[c]
    hi = lo + tab.fs_n[c]
    L, ext = tab.yarn_length[c], tab.yarn_extent[c]
    grid = np.linspace(0.0, L, 20001)
    P = np.array([_axis(tab, c, s) for s in grid])
    for s_true, r, a in zip(rng.uniform(0.1 * L, 0.9 * L, 60), ext * rng.uniform(0.1, 0.9, 60),
                            rng.uniform(0, 6.3, 60)):
        _, f = frame_at(tab.fs_s, tab.fs_frame, lo, hi, lo, s_true)
        p = np.array(eq7(f, r * math.cos(a), r * math.sin(a)))
        k = int(np.argmin(((P - p) ** 2).sum(1)))
        a_, b_ = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        for _ in range(80):  # golden section on the bracketing samples
            m1, m2 = b_ - 0.618 * (b_ - a_), a_ + 0.618 * (b_ - a_)
            if np.sum((_axis(tab, c, m1) - p) ** 2) < np.sum((_axis(tab, c, m2) - p) ** 2):
                b_ = m2
            else:
                a_ = m1
        s_ref = 0.5 * (a_ + b_)
        d2_ref = float(np.sum((_axis(tab, c, s_ref) - p) ** 2))
        sa, sb = max(0.0, s_ref - 0.05), min(L, s_ref + 0.05)
        ia = int(np.searchsorted(tab.fs_s[lo:hi], sa, side="right")) - 1 + lo
        ib = int(np.searchsorted(tab.fs_s[lo:hi], sb)) + lo + 1
        s, i, d2 = foot_point(tab.fs_s, tab.fs_frame, max(ia, lo), min(ib, hi), max(ia, lo),
                              s_ref + 0.03 * (rng.uniform() - 0.5), sa, sb, p[0], p[1], p[2], 1e-9)
        assert abs(s - s_ref) < 1e-6
        assert abs(math.sqrt(d2) - math.sqrt(d2_ref)) < 1e-9
        assert tab.fs_s[i] <= s <= tab.fs_s[i + 1]
