"""2. SSDFs (the package doc): each binary image's signed angular distance to its boundary, exact, O(D)
per image."""

import math

import numba
import numpy as np
from numba import njit, prange

from stages.precompute.svf.pixels import unpack_into


@njit(cache=True)
def ssdf_tables(res_theta, res_phi):
    """(sin theta, cos theta per row, 2 - 2 cos(k delta) per row offset k, sin^2(k pi / res_phi) per
    column offset k)."""
    d = math.pi / res_theta
    st = np.empty(res_theta)
    ct = np.empty(res_theta)
    dth = np.empty(res_theta)
    for r in range(res_theta):
        st[r] = math.sin((r + 0.5) * d)
        ct[r] = math.cos((r + 0.5) * d)
        dth[r] = 2.0 - 2.0 * math.cos(r * d)
    s2 = np.empty(res_phi // 2 + 1)
    for c in range(s2.shape[0]):
        v = math.sin(c * math.pi / res_phi)
        s2[c] = v * v
    return st, ct, dth, s2


@njit(cache=True)
def _row_distances(img, R, C, near):
    """near[v, r, c] = column distance (phi wraps) from (r, c) to the nearest pixel of value v in row r;
    -1 when the row has none."""
    for r in range(R):
        base = r * C
        for v in range(2):
            last = -1
            for c in range(C):
                if img[base + c] == v:
                    last = c
            if last < 0:
                for c in range(C):
                    near[v, r, c] = -1
                continue
            last -= C
            for c in range(C):          # forward sweep: distance to the nearest v at or before c
                if img[base + c] == v:
                    last = c
                near[v, r, c] = c - last
            nxt = -1
            for c in range(C):
                if img[base + c] == v:
                    nxt = c
                    break
            nxt += C
            for c in range(C - 1, -1, -1):   # backward sweep
                if img[base + c] == v:
                    nxt = c
                if nxt - c < near[v, r, c]:
                    near[v, r, c] = nxt - c


@njit(cache=True)
def ssdf_of_image(img, R, C, tabs, near, out):
    """SSDF (module doc) of the flat 0/1 image ``img`` (R*C,) into ``out`` (R*C,); ``tabs`` from
    ssdf_tables; scratch ``near`` (2, R, C) int32.

    For a pixel p of row r and a source row r' whose nearest pixel of the wanted value (in |dphi|, the
    row pass) is k columns away, p . q = cos th cos th' + sin th (sin th' cos(2 pi k / C)): for a fixed
    column, linear in p's (cos th, sin th) with the row's point (cos th', sin th' cos dphi'). The
    nearest q maximises p . q, so it is on the upper convex hull of the rows' points, and as th grows
    the maximiser moves along that hull one way: per column and value one hull (monotone chain, rows in
    order) and one sweep, O(R) each. The chosen row's chord^2 is then evaluated accurately as
    2 - 2 cos(th - th') + 4 sin th sin th' sin^2(dphi / 2)."""
    st, ct, dth, s2 = tabs
    D = R * C
    n1 = 0
    for i in range(D):
        n1 += img[i]
    if n1 == 0 or n1 == D:
        v = math.pi if n1 == D else -math.pi
        for i in range(D):
            out[i] = v
        return
    _row_distances(img, R, C, near)
    half = 0.5 * math.pi / R
    hull = np.empty(R, np.int64)
    hx = np.empty(R)
    hy = np.empty(R)
    for o in range(2):              # the value looked for; targets are the pixels of value 1 - o
        v = 1 - o
        for c in range(C):
            # upper hull of the rows holding o, taken right to left (cos th' decreasing): left turns only
            H = 0
            for r2 in range(R):
                kk = near[o, r2, c]
                if kk < 0:
                    continue
                x = ct[r2]
                y = st[r2] * (1.0 - 2.0 * s2[kk])
                while H >= 2 and (hx[H - 1] - hx[H - 2]) * (y - hy[H - 2]) - \
                        (hy[H - 1] - hy[H - 2]) * (x - hx[H - 2]) <= 0.0:
                    H -= 1
                hull[H] = r2
                hx[H] = x
                hy[H] = y
                H += 1
            h = 0
            for r in range(R):
                ux = ct[r]
                uy = st[r]
                while h + 1 < H and ux * hx[h + 1] + uy * hy[h + 1] >= ux * hx[h] + uy * hy[h]:
                    h += 1
                i = r * C + c
                if img[i] != v:
                    continue
                r2 = hull[h]
                ch = dth[abs(r - r2)] + 4.0 * st[r] * st[r2] * s2[near[o, r2, c]]
                g = 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(ch)))
                m = max(g - half, 0.5 * g)
                out[i] = m if v == 1 else -m


@njit(cache=True)
def segment_ssdf(packed, s, R, C, tabs):
    """(binary image, SSDF) of packed image s (R x C pixels, flattened; ``tabs`` from ``ssdf_tables``)."""
    D = R * C
    img = np.empty(D, np.uint8)
    near = np.empty((2, R, C), np.int32)
    buf = np.empty(D)
    unpack_into(packed, s, img)
    ssdf_of_image(img, R, C, tabs, near, buf)
    return img, buf


@njit(cache=True, parallel=True)
def _ssdf_kernel(packed, R, C, out):
    tabs = ssdf_tables(R, C)
    D = R * C
    for s in prange(packed.shape[0]):
        _img, buf = segment_ssdf(packed, s, R, C, tabs)
        for i in range(D):
            out[s, i] = buf[i]


def ssdf_images(packed, res_theta: int, res_phi: int):
    """Chunk level. SSDFs (S, D) float32 of bit-packed images (module doc: angle in radians, + visible)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    out = np.empty((packed.shape[0], res_theta * res_phi), np.float32)
    if packed.shape[0]:
        with numba.parallel_chunksize(1):
            _ssdf_kernel(packed, res_theta, res_phi, out)
    return out
