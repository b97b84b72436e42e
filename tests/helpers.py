"""Paths and reference data every test may need. ../shared is reference material: tests that use it
skip (``shared_file``) when it is absent."""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
DATA = ROOT / "data"

# the gentle swatch (exact lookups): scene text of the lookups' exactness and frame-sample tests
EXACTNESS_SWATCH = (DATA / "scenes" / "gentle_swatch.toml").read_text()


def shared_file(rel: str) -> Path:
    p = SHARED / rel
    if not p.exists():
        pytest.skip(f"reference file ../shared/{rel} is not present "
                    "(../shared is reference material, absent on this machine)")
    return p


def closed_ring_scene(d: Path):
    """A closed yarn (a gently waved ring of 24 Catmull-Rom points, BCC negative count) written to
    ``d/ring.bcc``: (its control points (24, 3), the scene text that ingests it as cotton2)."""
    import numpy as np

    from pipeline.curveset import CurveSet
    from pipeline.io import bcc

    th = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    ring = np.c_[0.6 * np.cos(th), 0.6 * np.sin(th), 0.02 * np.sin(3.0 * th)]
    bcc.write(d / "ring.bcc", CurveSet(points=[ring], closed=[True], group=["other"],
                                       point_radius=[np.full(len(ring), 0.03)], curve_type="catmull-rom",
                                       source_format="bcc", notes={}))
    scene = ('[scene]\nname = "ring"\n[fabric]\nsource = "file"\n'
             f'path = "{d / "ring.bcc"}"\nradius = 0.03\n[yarns.default]\npreset = "cotton2"\n')
    return ring, scene


def seam_points(fib, ring, n_seam: int, n_all: int):
    """Points around a closed ring's seam (realized vertices within 0.08 of its first control point)
    and anywhere on it, jittered by 1.5 fibre radii (seed 0)."""
    import numpy as np

    pts = np.asarray(fib["points"], np.float64)
    rf = float(np.max(fib["point_radius"]))
    rng = np.random.default_rng(0)
    seam = pts[np.linalg.norm(pts - ring[0], axis=1) < 0.08]
    Q = np.concatenate([seam[rng.integers(0, len(seam), n_seam)], pts[rng.integers(0, len(pts), n_all)]])
    return Q + rng.normal(0.0, 1.5 * rf, Q.shape)


def compiled_typings(dispatcher) -> set:
    """The typings a numba dispatcher has been compiled for: those compiled in this process
    (``.signatures``) and those in its on-disk cache index. On a warm cache its callers load their own
    machine code and never compile it here, so ``.signatures`` alone is empty; the index (in the
    cache directory ``stages`` keys by the kernel sources) still lists every typing any process compiled."""
    typings = {str(sig) for sig in dispatcher.signatures}
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is not None:
        typings |= {str(key[0]) for key in cache_file._load_index()}
    return typings
