"""stages/core/geometry/frames.py: face_towards_into against its contract (module doc): a normal facing the
direction by at least c_min is left bit for bit; one facing away ends a unit vector in the plane of n and w
with n.w > 0 (the value before renormalising is c_min exactly, so after it c_min / |n + k w|)."""
import numpy as np

from stages.core.geometry.frames import face_towards_into


def test_face_towards_into():
    rng = np.random.default_rng(4)
    for _ in range(200):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        w = rng.normal(size=3)
        w /= np.linalg.norm(w)
        c_min = 1e-3
        before = n.copy()
        c = float(n @ w)
        bent = face_towards_into(n, w, c_min)
        if c >= c_min:
            assert not bent and n.tobytes() == before.tobytes()
            continue
        assert bent
        assert abs(np.linalg.norm(n) - 1.0) < 1e-12
        unnormalised = before + (c_min - c) * w
        np.testing.assert_allclose(n, unnormalised / np.linalg.norm(unnormalised), rtol=1e-12, atol=1e-15)
        assert float(n @ w) > 0.0
        assert abs(float(np.cross(before, w) @ n)) < 1e-12       # in the plane of n and w
