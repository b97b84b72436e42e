"""Image error metrics: a test image against a reference image, both linear RGB (H, W, 3).

Every metric is a pure function of two arrays; the sums are taken per row in parallel and then
added in a fixed order, so results are the same bytes whatever the thread count.

- ``rmse(test, ref)``: root mean squared error over all pixels and the three channels,
  sqrt(mean((t - r)^2)). A constant offset c gives exactly |c|.
- ``relmse(test, ref, eps=0.01)``: relative MSE, mean over pixels and channels of
  (t - r)^2 / (r^2 + eps) (the per-pixel squared error over the reference squared plus 0.01).
- ``luminance(rgb)``: Y = 0.2126 R + 0.7152 G + 0.0722 B (linear sRGB / Rec. 709 primaries).
- ``ssim_input(rgb)``: what SSIM is computed on: the luminance clipped to [0, 1] and sRGB-encoded,
  i.e. the grey level a viewer sees in the PNG preview at exposure 0, with dynamic range L = 1.
- ``ssim(x, y)``: mean SSIM of Wang, Bovik, Sheikh & Simoncelli 2004 (Eq. 13) on two grey images
  with values in [0, L]: an 11x11 Gaussian window with sigma = 1.5 (normalised to sum 1), constants
  C1 = (K1 L)^2, C2 = (K2 L)^2 with K1 = 0.01, K2 = 0.03, L = 1, statistics weighted by the window,
  and the SSIM map averaged over the window positions that lie wholly inside the image ("valid"
  filtering, as in the authors' reference code). Images must be at least 11x11.
- ``ssim_map(x, y)``: the per-window SSIM values, (H - 10, W - 10).
- ``mean_intensity(rgb)``: per-channel mean, the "average intensity" of seed 001 §6.3 (Fig. 13
  compares these, 3 values per image, across light configurations).
- ``rgb_to_lab(rgb)``: linear sRGB (clipped to [0, 1], as shown by the preview) -> CIE XYZ -> CIE
  L*a*b* under D65 with white Y = 1, through colour-science.
- ``delta_e2000(lab_a, lab_b)``: CIEDE2000 colour difference (Sharma, Wu & Dalal 2005) through
  colour-science; ``delta_e2000_map(test, ref)`` is the per-pixel map of two linear RGB images.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

SSIM_K1 = 0.01
SSIM_K2 = 0.03
SSIM_SIGMA = 1.5
SSIM_WINDOW = 11
RELMSE_EPS = 0.01
LUMA = (0.2126, 0.7152, 0.0722)


# ------------------------------------------------------------------------------------------------
# pixel-wise errors
@njit(cache=True, parallel=True)
def _row_sq_err(t, r, eps, relative):
    h, w, c = t.shape
    rows = np.zeros(h)
    for i in prange(h):
        s = 0.0
        for j in range(w):
            for k in range(c):
                d = float(t[i, j, k]) - float(r[i, j, k])
                if relative:
                    rr = float(r[i, j, k])
                    s += d * d / (rr * rr + eps)
                else:
                    s += d * d
        rows[i] = s
    return rows


def _as3(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim == 2:
        a = a[:, :, None]
    return np.ascontiguousarray(a, dtype=np.float64)


def rmse(test: np.ndarray, ref: np.ndarray) -> float:
    t, r = _as3(test), _as3(ref)
    return math.sqrt(float(np.sum(_row_sq_err(t, r, 0.0, False))) / t.size)


def relmse(test: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> float:
    t, r = _as3(test), _as3(ref)
    return float(np.sum(_row_sq_err(t, r, float(eps), True))) / t.size


@njit(cache=True, parallel=True)
def _luminance(rgb, out):
    h, w, _ = rgb.shape
    for i in prange(h):
        for j in range(w):
            out[i, j] = 0.2126 * rgb[i, j, 0] + 0.7152 * rgb[i, j, 1] + 0.0722 * rgb[i, j, 2]


def luminance(rgb: np.ndarray) -> np.ndarray:
    rgb = np.ascontiguousarray(rgb, dtype=np.float64)
    out = np.empty(rgb.shape[:2])
    _luminance(rgb, out)
    return out


@njit(cache=True, parallel=True)
def _srgb_encode(y, out):
    h, w = y.shape
    for i in prange(h):
        for j in range(w):
            v = min(max(y[i, j], 0.0), 1.0)
            if v <= 0.0031308:
                out[i, j] = 12.92 * v
            else:
                out[i, j] = 1.055 * v ** (1.0 / 2.4) - 0.055


def ssim_input(rgb: np.ndarray) -> np.ndarray:
    """Clipped, sRGB-encoded luminance in [0, 1]: the grey image SSIM is computed on (L = 1)."""
    y = luminance(rgb)
    out = np.empty_like(y)
    _srgb_encode(y, out)
    return out


@njit(cache=True, parallel=True)
def _channel_means(rgb):
    h, w, c = rgb.shape
    rows = np.zeros((h, c))
    for i in prange(h):
        for j in range(w):
            for k in range(c):
                rows[i, k] += rgb[i, j, k]
    out = np.zeros(c)
    for i in range(h):
        for k in range(c):
            out[k] += rows[i, k]
    return out / (h * w)


def mean_intensity(rgb: np.ndarray) -> np.ndarray:
    """Per-channel mean of an (H, W, C) image (seed 001 §6.3 'average intensity')."""
    return _channel_means(_as3(rgb))


# ------------------------------------------------------------------------------------------------
# SSIM
def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    """1-D Gaussian weights g; the 2-D window is the outer product g g^T (sums to 1)."""
    x = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    g = np.exp(-0.5 * (x / sigma) ** 2)
    return g / g.sum()


@njit(cache=True, parallel=True)
def _ssim_map(x, y, g, c1, c2, out):
    h, w = x.shape
    n = g.shape[0]
    oh, ow = out.shape
    # horizontal pass of the five moment images, valid columns only
    hx = np.empty((h, ow))
    hy = np.empty((h, ow))
    hxx = np.empty((h, ow))
    hyy = np.empty((h, ow))
    hxy = np.empty((h, ow))
    for i in prange(h):
        for j in range(ow):
            sx = 0.0
            sy = 0.0
            sxx = 0.0
            syy = 0.0
            sxy = 0.0
            for k in range(n):
                a = x[i, j + k]
                b = y[i, j + k]
                wk = g[k]
                sx += wk * a
                sy += wk * b
                sxx += wk * a * a
                syy += wk * b * b
                sxy += wk * a * b
            hx[i, j] = sx
            hy[i, j] = sy
            hxx[i, j] = sxx
            hyy[i, j] = syy
            hxy[i, j] = sxy
    # vertical pass and the SSIM formula (Wang et al. 2004, Eq. 13)
    for i in prange(oh):
        for j in range(ow):
            mx = 0.0
            my = 0.0
            mxx = 0.0
            myy = 0.0
            mxy = 0.0
            for k in range(n):
                wk = g[k]
                mx += wk * hx[i + k, j]
                my += wk * hy[i + k, j]
                mxx += wk * hxx[i + k, j]
                myy += wk * hyy[i + k, j]
                mxy += wk * hxy[i + k, j]
            vx = mxx - mx * mx
            vy = myy - my * my
            cov = mxy - mx * my
            out[i, j] = ((2.0 * mx * my + c1) * (2.0 * cov + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def ssim_map(x: np.ndarray, y: np.ndarray, dynamic_range: float = 1.0,
             window: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2:
        raise ValueError(f"ssim needs two grey images of one shape, got {x.shape} and {y.shape}")
    if x.shape[0] < window or x.shape[1] < window:
        raise ValueError(f"ssim needs images of at least {window}x{window} pixels, got {x.shape[1]}x{x.shape[0]}")
    c1 = (SSIM_K1 * dynamic_range) ** 2
    c2 = (SSIM_K2 * dynamic_range) ** 2
    out = np.empty((x.shape[0] - window + 1, x.shape[1] - window + 1))
    _ssim_map(x, y, gaussian_window(window, sigma), c1, c2, out)
    return out


def ssim(x: np.ndarray, y: np.ndarray, dynamic_range: float = 1.0) -> float:
    m = ssim_map(x, y, dynamic_range)
    return float(np.sum(np.sum(m, axis=1)) / m.size)


# ------------------------------------------------------------------------------------------------
# CIEDE2000 (colour-science)
def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """Linear sRGB clipped to [0, 1] -> CIE L*a*b* (D65, white Y = 1)."""
    import colour

    cs = colour.RGB_COLOURSPACES["sRGB"]
    lin = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)
    xyz = colour.RGB_to_XYZ(lin, cs, apply_cctf_decoding=False)
    return colour.XYZ_to_Lab(xyz, cs.whitepoint)


def delta_e2000(lab_a: np.ndarray, lab_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 between two arrays of L*a*b* triples (Sharma et al. 2005)."""
    import colour

    return np.asarray(colour.delta_E(np.asarray(lab_a, float), np.asarray(lab_b, float), method="CIE 2000"))


def delta_e2000_map(test: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return delta_e2000(rgb_to_lab(test), rgb_to_lab(ref))
