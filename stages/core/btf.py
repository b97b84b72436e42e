"""The fitted cloth texture of seed 002 as its fit and its renderer read it (Daubert et al. 2001, §3).

One texel of a repeat holds a spatially varying BRDF (Eq. 1-2):

    f_r(l, v) = T(v) . f_1(l, v),    f_1(l, v) = l_z (rho + sum_i [C_x l'_x v'_x + C_y l'_y v'_y + C_z l'_z v'_z]^N_i)

per colour channel, where ``a^N`` is 0 for a <= 0 (the paper's footnote 3). Directions are unit vectors
pointing away from the surface (towards the light, towards the viewer):

- **pattern space**: the repeat's own frame, x and y in the fabric plane (x along the exemplar's x axis,
  the warp ends' spacing direction; y along its y axis), z its macro normal. ``l_z`` is the light's
  pattern-space z: the foreshortening of the fabric plane, >= 0 for every light the fit saw.
- **texel frame**: the texel's average normal n and tangent t (``frame`` rows 0 and 1, pattern space),
  b = n x t; ``l' = (l.t, l.b, l.n)``. The lobes use l', v' (§3: "transform the light and viewing
  direction into the local coordinate system given by the sampling point's average normal and tangent").

``f_r`` is radiance per unit irradiance: a directional light of irradiance E (perpendicular to its
beam) from l makes the texel send E f_r(l, v) towards v. Acquisition (``stages.precompute.btf``)
measures exactly that, so the fit needs no cosine of its own beyond the model's l_z.

The lookup table T(v) (and the alpha of each view) is stored on a grid of view directions:
``hemisphere_grid(n_theta, n_phi)`` puts n_theta rings of equal solid angle (cos theta_i = 1 - (i + 1/2)
/ n_theta) times n_phi azimuths (phi_j = 2 pi (j + 1/2) / n_phi), ring-major (index i n_phi + j); every
direction stands for the same solid angle 2 pi / (n_theta n_phi). ``grid_weights`` gives a direction's
bilinear interpolation weights on that grid (rings clamped at the pole and the horizon, azimuth
wrapped), so T(v) and alpha are continuous in v. Light directions use the same grid, and the sum over
it is the renderer's quadrature for environment and SG lights.
"""
import math

import numpy as np
from numba import njit, prange

TWO_PI = 2.0 * math.pi
LOBE_PARAMS = 4          # C_x, C_y, C_z, N


def hemisphere_grid(n_theta: int, n_phi: int) -> np.ndarray:
    """(n_theta n_phi, 3) unit directions of the upper hemisphere, ring-major (module doc)."""
    i = np.arange(n_theta)
    j = np.arange(n_phi)
    cos_t = 1.0 - (i + 0.5) / n_theta
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = TWO_PI * (j + 0.5) / n_phi
    d = np.empty((n_theta, n_phi, 3))
    d[..., 0] = sin_t[:, None] * np.cos(phi)[None, :]
    d[..., 1] = sin_t[:, None] * np.sin(phi)[None, :]
    d[..., 2] = cos_t[:, None]
    return d.reshape(-1, 3)


@njit(cache=True)
def cell_direction(index, n_theta, n_phi, u0, u1):
    """(x, y, z): the direction at (u0, u1) in [0, 1)^2 of cell ``index`` of the hemisphere grid
    (``hemisphere_grid``: ring i = index // n_phi, cos theta in [1 - (i+1)/n_theta,
    1 - i/n_theta]; azimuth j = index % n_phi, phi in [2 pi j/n_phi, 2 pi (j+1)/n_phi]); uniform (u0, u1)
    give directions uniform in the cell's solid angle, (0.5, 0.5) the grid direction itself."""
    i = index // n_phi
    j = index - i * n_phi
    ct = 1.0 - (i + u0) / n_theta
    st = math.sqrt(max(0.0, 1.0 - ct * ct))
    phi = 2.0 * math.pi * (j + u1) / n_phi
    return st * math.cos(phi), st * math.sin(phi), ct


@njit(cache=True)
def grid_weights(n_theta, n_phi, vx, vy, vz):
    """Bilinear weights of direction v (pattern space, need not be normalised) on the hemisphere grid:
    (i0, i1, i2, i3, w0, w1, w2, w3), indices into the ring-major table."""
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    cz = min(1.0, max(0.0, vz / n)) if n > 0.0 else 1.0
    a = (1.0 - cz) * n_theta - 0.5
    a = min(max(a, 0.0), n_theta - 1.0)
    r0 = int(math.floor(a))
    r1 = min(r0 + 1, n_theta - 1)
    fa = a - r0
    phi = math.atan2(vy, vx)
    if phi < 0.0:
        phi += TWO_PI
    b = phi * n_phi / TWO_PI - 0.5
    c0f = math.floor(b)
    fb = b - c0f
    c0 = int(c0f) % n_phi
    c1 = (c0 + 1) % n_phi
    return (r0 * n_phi + c0, r0 * n_phi + c1, r1 * n_phi + c0, r1 * n_phi + c1,
            (1.0 - fa) * (1.0 - fb), (1.0 - fa) * fb, fa * (1.0 - fb), fa * fb)


@njit(cache=True, inline="always")
def lafortune_lobe(cx, cy, cz, n, lx, ly, lz, vx, vy, vz):
    """[C_x l_x v_x + C_y l_y v_y + C_z l_z v_z]^N, 0 where the bracket is <= 0 (Eq. 2, footnote 3);
    l, v in the texel frame."""
    a = cx * lx * vx + cy * ly * vy + cz * lz * vz
    if a <= 0.0:
        return 0.0
    return a ** n


@njit(cache=True, inline="always")
def to_texel_frame(frame, x, y, z):
    """Pattern-space direction into the texel frame (t, b = n x t, n) of ``frame`` (2, 3): (n, t)."""
    nx, ny, nz = frame[0, 0], frame[0, 1], frame[0, 2]
    tx, ty, tz = frame[1, 0], frame[1, 1], frame[1, 2]
    bx = ny * tz - nz * ty
    by = nz * tx - nx * tz
    bz = nx * ty - ny * tx
    return (x * tx + y * ty + z * tz, x * bx + y * by + z * bz, x * nx + y * ny + z * nz)


@njit(cache=True)
def texel_f1(rho, lobes, frame, c, lx, ly, lz, vx, vy, vz):
    """f_1(l, v) of channel c (Eq. 2): ``rho`` (3,), ``lobes`` (K, 3, 4), ``frame`` (2, 3); l, v unit
    pattern-space directions. 0 for a light below the fabric plane (l_z <= 0)."""
    if lz <= 0.0:
        return 0.0
    ax, ay, az = to_texel_frame(frame, lx, ly, lz)
    bx, by, bz = to_texel_frame(frame, vx, vy, vz)
    s = rho[c]
    for k in range(lobes.shape[0]):
        s += lafortune_lobe(lobes[k, c, 0], lobes[k, c, 1], lobes[k, c, 2], lobes[k, c, 3], ax, ay, az, bx, by, bz)
    return lz * s


@njit(cache=True)
def table_lookup(table, n_theta, n_phi, vx, vy, vz, c):
    """T(v) channel c (0-2) or alpha (c = 3), bilinear on the view grid; ``table`` (V, 4)."""
    i0, i1, i2, i3, w0, w1, w2, w3 = grid_weights(n_theta, n_phi, vx, vy, vz)
    return w0 * table[i0, c] + w1 * table[i1, c] + w2 * table[i2, c] + w3 * table[i3, c]


@njit(cache=True, parallel=True)
def decode_texels(cluster, mean, basis, weights, out, clamp):
    """The tabulated texture's rows (``stages.precompute.btf_compress``): out[t] = mean[c] + sum_k weights[t, k]
    basis[c, k] with c = cluster[t] (float64 sums, k ascending; stored float32). ``clamp``: negative values
    (a truncated expansion can undershoot near 0) become 0, as radiance must. ``cluster`` (T,), ``mean`` (C, D),
    ``basis`` (C, K, D), ``weights`` (T, K), ``out`` (T, D)."""
    T, D = out.shape
    K = weights.shape[1]
    for t in prange(T):
        c = cluster[t]
        for d in range(D):
            acc = np.float64(mean[c, d])
            for k in range(K):
                acc += np.float64(weights[t, k]) * np.float64(basis[c, k, d])
            out[t, d] = max(acc, 0.0) if clamp else acc


@njit(cache=True)
def table_rgb(radiance, idx, lt, lph, lx, ly, lz, vt, vph, vx, vy, vz):
    """The tabulated texture's f_1(l, v) = r(l, v), three channels, of texel row idx: ``radiance`` (N, V, L, 3)
    bilinear on the view grid (vt x vph) and on the light grid (lt x lph) (``grid_weights``: exact at the grid's
    directions); 0 for l_z <= 0. r holds the light's l_z as f_1 does (radiance per unit irradiance). A plain call,
    not inlined: inlined at the btf tile loop's six call sites it added 20 s to its first compilation."""
    if lz <= 0.0:
        return 0.0, 0.0, 0.0
    a0, a1, a2, a3, p0, p1, p2, p3 = grid_weights(vt, vph, vx, vy, vz)
    b0, b1, b2, b3, q0, q1, q2, q3 = grid_weights(lt, lph, lx, ly, lz)
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for iv, wv in ((a0, p0), (a1, p1), (a2, p2), (a3, p3)):
        if wv == 0.0:
            continue
        r = radiance
        s0 += wv * (q0 * r[idx, iv, b0, 0] + q1 * r[idx, iv, b1, 0] + q2 * r[idx, iv, b2, 0] + q3 * r[idx, iv, b3, 0])
        s1 += wv * (q0 * r[idx, iv, b0, 1] + q1 * r[idx, iv, b1, 1] + q2 * r[idx, iv, b2, 1] + q3 * r[idx, iv, b3, 1])
        s2 += wv * (q0 * r[idx, iv, b0, 2] + q1 * r[idx, iv, b1, 2] + q2 * r[idx, iv, b2, 2] + q3 * r[idx, iv, b3, 2])
    return s0, s1, s2
