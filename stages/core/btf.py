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

**Half-vector light cells** (``light_coords = HALF``; ``precompute btf --light-coords half``). A fibre's glint is
where its tangent t is perpendicular to the half vector h = (l + v) / |l + v|, and a yarn of twist angle a
along x holds fibres whose tangents make every angle up to a with it, so its floats glint for |h_x| <= sin a
whatever the view (Rusinkiewicz 1998 chose half-vector coordinates for the same reason: specular features
sit still in them). A cell of the hemisphere grid that a glint's edge crosses averages bright and dark; cells
of the half vector put those edges near cell boundaries, the same ones for every view. So the light of cell j
of an ``nx`` x ``ny`` grid over the square of projected half vectors (h_x, h_y) in [-1, 1]^2 (column
ix = j % nx, row iy = j // nx, centre h_x = -1 + 2 (ix + 1/2) / nx) seen from v is the mirror direction of v
about h: l = 2 (v.h) h - v (``half_cell_direction``). Not every (h, v) gives a light above
the fabric (|h_xy| >= 1, v.h <= 0 or l_z <= 0: *invalid*, no light); ``half_cell_geometry`` gives each (view
cell, light cell) its valid fraction (of the cell's h area: the acquisition's samples there carry the light,
the others 0) and its solid angle (the light directions whose half vector with v lies in the cell: the
cells partition the hemisphere, summing to 2 pi for every view). The acquisition's cell averages are over
the whole cell (invalid samples 0); a read normalises them by the valid fraction, which makes a cell cut by
the horizon the mean over the part that has light (``half_row``).

A read at (l, v) (``half_rgb``) interpolates the view grid's four rows at the light l itself, each row's cells
at the half vector of l and that row's own view -- as the hemisphere grid does, with the light axis in
half-vector cells. Reading every row at the half vector of (l, v) instead keeps a glint on one cell across
the rows but mirrors each row's view to another light: 45 degrees of view azimuth apart, lights whose l_z
differ by a quarter (0.53 and 0.71 for the flat satins' camera under the light 45 degrees from the normal), and
r carries the light's foreshortening, so that read came out 7-8 % dark there on the satins; dividing the
foreshortening out of the cells and back in at the light came out 2-12 % bright on the satins (r of a layer of
fibres is not proportional to l_z), though it was the best read of the knit (``make btf-sweep``, CHANGES
2026-12-06).

**Light from below** (``light_coords = SPHERE``; ``precompute btf --light-domain sphere``, the tabulated model). Seed
002's texture is a reflectance: its lights lie above the fabric. Cloth lit from behind (a curtain against a window,
a knit under a sky that is as bright below the swatch as above it) sends light through itself. A sphere table holds
the hemisphere grid's L cells and then their mirror images below the fabric (cell L + k is cell k with l_z negated,
``sphere_cell_direction``): its light axis is 2 L long, and a read with l_z < 0 reads the lower half at (l_x, l_y,
-l_z) (``table_rgb``). r(l, v) there is the radiance towards v per unit irradiance of a light behind the fabric --
what comes through the holes and the yarns, the fabric's own shadowing included.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

TWO_PI = 2.0 * math.pi
LOBE_PARAMS = 4          # C_x, C_y, C_z, N
HEMISPHERE = 0           # light coordinates: the hemisphere grid (the default) ...
HALF = 1                 # ... or half-vector cells (module doc) ...
SPHERE = 2               # ... or the hemisphere grid and its mirror image below the fabric (module doc)
MIN_VALID = 1e-6         # a view row of the half-vector table whose light weights' valid fraction is below this
                         # holds no light near the direction: it is left out of the view interpolation
GEOMETRY_SUB = 8         # ``half_cell_geometry``: sub-samples per axis of a view cell and of a light cell

HalfCells = namedtuple("HalfCells", ["valid", "solid"])
HalfCells.__doc__ = """What a half-vector light grid is seen from each view cell (``half_cell_geometry``), each (V, L):
the cells' valid fractions and solid angles."""


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


def sphere_grid(n_theta: int, n_phi: int) -> np.ndarray:
    """(2 n_theta n_phi, 3) a sphere table's light cells (module doc, "Light from below"): the hemisphere grid, then
    its mirror image below the fabric (``sphere_cell_direction`` at the cells' centres)."""
    grid = hemisphere_grid(n_theta, n_phi)
    return np.concatenate([grid, grid * np.array([1.0, 1.0, -1.0])])


def half_grid(nx: int, ny: int) -> np.ndarray:
    """(nx ny, 3) the centre half vectors of the nx x ny half-vector cells (module doc; ``half_cell_direction`` at
    (0.5, 0.5)), row-major in h_y; h_z 0 for a centre off the unit disk."""
    hx, hy = np.meshgrid(-1.0 + 2.0 * (np.arange(nx) + 0.5) / nx, -1.0 + 2.0 * (np.arange(ny) + 0.5) / ny)
    hz = np.sqrt(np.maximum(0.0, 1.0 - hx * hx - hy * hy))
    return np.stack([hx, hy, hz], axis=-1).reshape(-1, 3)


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
def sphere_cell_direction(index, n_theta, n_phi, u0, u1):
    """``cell_direction`` of a sphere table's light cell ``index`` (module doc, "Light from below"): cells 0 .. n - 1
    (n = n_theta n_phi) the hemisphere grid's, cells n .. 2 n - 1 their mirror images below the fabric."""
    n = n_theta * n_phi
    if index < n:
        return cell_direction(index, n_theta, n_phi, u0, u1)
    x, y, z = cell_direction(index - n, n_theta, n_phi, u0, u1)
    return x, y, -z


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


@njit(cache=True)
def half_cell_direction(index, nx, ny, u0, u1, vx, vy, vz):
    """(l_x, l_y, l_z): the light at (u0, u1) in [0, 1)^2 of cell ``index`` of the nx x ny half-vector grid seen from
    the unit view v (module doc): l = 2 (v.h) h - v, and (0, 0, -1) -- l_z <= 0: no light -- where h is off the
    unit disk, faces away from v, or mirrors v below the fabric. (0.5, 0.5) is the cell's centre."""
    iy = index // nx
    ix = index - iy * nx
    hx = -1.0 + 2.0 * (ix + u0) / nx
    hy = -1.0 + 2.0 * (iy + u1) / ny
    s = hx * hx + hy * hy
    if s >= 1.0:
        return 0.0, 0.0, -1.0
    hz = math.sqrt(1.0 - s)
    d = hx * vx + hy * vy + hz * vz
    if d <= 0.0:
        return 0.0, 0.0, -1.0
    lz = 2.0 * d * hz - vz
    if lz <= 0.0:
        return 0.0, 0.0, -1.0
    return 2.0 * d * hx - vx, 2.0 * d * hy - vy, lz


@njit(cache=True)
def half_weights(nx, ny, lx, ly, lz, vx, vy, vz):
    """Bilinear weights of the half vector of l and v (unit, or any length) on the nx x ny half-vector grid's cell
    centres, clamped at the square's edges: (i0, i1, i2, i3, w0, w1, w2, w3), indices into the light axis."""
    ln = math.sqrt(lx * lx + ly * ly + lz * lz)
    vn = math.sqrt(vx * vx + vy * vy + vz * vz)
    hx = lx / ln + vx / vn
    hy = ly / ln + vy / vn
    hz = lz / ln + vz / vn
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    a = min(max((hx / hn + 1.0) * 0.5 * nx - 0.5, 0.0), nx - 1.0)
    b = min(max((hy / hn + 1.0) * 0.5 * ny - 0.5, 0.0), ny - 1.0)
    c0 = int(math.floor(a))
    r0 = int(math.floor(b))
    c1 = min(c0 + 1, nx - 1)
    r1 = min(r0 + 1, ny - 1)
    fa = a - c0
    fb = b - r0
    return (r0 * nx + c0, r0 * nx + c1, r1 * nx + c0, r1 * nx + c1,
            (1.0 - fb) * (1.0 - fa), (1.0 - fb) * fa, fb * (1.0 - fa), fb * fa)


@njit(cache=True, parallel=True)
def half_cell_geometry(vt, vph, nx, ny, jitter):
    """``HalfCells`` (valid (V, L), solid (V, L)) of the nx x ny half-vector grid seen from each cell of the vt x vph
    view grid (module doc): the fraction of light cell j's h area that gives a light above the fabric, and the
    solid angle of the lights whose half vector with the view lies in cell j, the integral of the Jacobian
    |dl/dh| = 4 (v.h) / h_z (dl = 4 (v.h) dh, dh = dh_x dh_y / h_z) over the cell's valid part, both by the
    midpoint rule on GEOMETRY_SUB^2 points; each view's solid angles then scaled to 2 pi (the rule under-counts the
    cells on the unit circle, where 1 / h_z grows without bound; the interior cells agree with light directions
    binned by their cell to the binning's resolution, within 1.5 % binning 131,072). ``jitter``: averaged over
    GEOMETRY_SUB^2 views spread over the view's cell, as the acquisition's cell averages see it; else at the grid
    view itself."""
    V = vt * vph
    L = nx * ny
    valid = np.zeros((V, L))
    solid = np.zeros((V, L))
    G = GEOMETRY_SUB
    S = G if jitter else 1
    area = 4.0 / (nx * ny * G * G * S * S)     # one h point's share of its cell's area, over the S^2 views
    for iv in prange(V):
        for a in range(S):
            for b in range(S):
                vx, vy, vz = cell_direction(iv, vt, vph, (a + 0.5) / S, (b + 0.5) / S)
                for j in range(L):
                    iy = j // nx
                    ix = j - iy * nx
                    for c in range(G):
                        for d in range(G):
                            hx = -1.0 + 2.0 * (ix + (c + 0.5) / G) / nx
                            hy = -1.0 + 2.0 * (iy + (d + 0.5) / G) / ny
                            if half_cell_direction(j, nx, ny, (c + 0.5) / G, (d + 0.5) / G, vx, vy, vz)[2] <= 0.0:
                                continue
                            hz = math.sqrt(1.0 - hx * hx - hy * hy)
                            valid[iv, j] += 1.0 / (G * G * S * S)
                            solid[iv, j] += area * 4.0 * (hx * vx + hy * vy + hz * vz) / hz
        total = 0.0
        for j in range(L):
            total += solid[iv, j]
        for j in range(L):
            solid[iv, j] *= TWO_PI / total
    return HalfCells(valid, solid)


@njit(cache=True)
def half_row(radiance, valid, idx, iv, b0, b1, b2, b3, q0, q1, q2, q3):
    """(r, g, b, valid fraction) of view row iv of texel row idx of a half-vector table at the light weights
    (``half_weights``): the weighted cell averages over the weighted valid fractions -- the mean radiance where
    the cells have light; (0, 0, 0, den) when the valid fraction ``den`` is below MIN_VALID."""
    den = q0 * valid[iv, b0] + q1 * valid[iv, b1] + q2 * valid[iv, b2] + q3 * valid[iv, b3]
    if den < MIN_VALID:
        return 0.0, 0.0, 0.0, den
    r = radiance
    s0 = q0 * r[idx, iv, b0, 0] + q1 * r[idx, iv, b1, 0] + q2 * r[idx, iv, b2, 0] + q3 * r[idx, iv, b3, 0]
    s1 = q0 * r[idx, iv, b0, 1] + q1 * r[idx, iv, b1, 1] + q2 * r[idx, iv, b2, 1] + q3 * r[idx, iv, b3, 1]
    s2 = q0 * r[idx, iv, b0, 2] + q1 * r[idx, iv, b1, 2] + q2 * r[idx, iv, b2, 2] + q3 * r[idx, iv, b3, 2]
    return s0 / den, s1 / den, s2 / den, den


@njit(cache=True)
def half_rgb(radiance, valid, idx, lnx, lny, lx, ly, lz, vt, vph, vx, vy, vz):
    """``table_rgb`` of a half-vector table (module doc): r(l, v) of texel row idx, three channels, bilinear on the view
    grid (vt x vph) and, in each of the four view rows, on the half-vector grid (lnx x lny) at the half vector of l
    and the row's grid view (``half_row``); the rows without light there left out and the others' weights
    renormalised; 0 for l_z <= 0. ``valid`` (V, L): ``HalfCells.valid``.
    13 parameters: ``table_rgb``'s twelve (the table, the row, both grids' shapes, l and v as scalars) and the cells'
    valid fractions; a plain call from the btf tile loop, as ``table_rgb``."""
    if lz <= 0.0:
        return 0.0, 0.0, 0.0
    a0, a1, a2, a3, p0, p1, p2, p3 = grid_weights(vt, vph, vx, vy, vz)
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    wsum = 0.0
    for iv, wv in ((a0, p0), (a1, p1), (a2, p2), (a3, p3)):
        if wv == 0.0:
            continue
        gx, gy, gz = cell_direction(iv, vt, vph, 0.5, 0.5)     # the row's grid view
        b0, b1, b2, b3, q0, q1, q2, q3 = half_weights(lnx, lny, lx, ly, lz, gx, gy, gz)
        r0, r1, r2, den = half_row(radiance, valid, idx, iv, b0, b1, b2, b3, q0, q1, q2, q3)
        if den < MIN_VALID:
            continue
        s0 += wv * r0
        s1 += wv * r1
        s2 += wv * r2
        wsum += wv
    if wsum <= 0.0:
        return 0.0, 0.0, 0.0
    return s0 / wsum, s1 / wsum, s2 / wsum


@njit(cache=True, parallel=True)
def half_to_hemisphere(radiance, valid, lnx, lny, view_dirs, light_dirs):
    """A half-vector table (T, V, L, 3) read at other lights (``light_dirs`` (M, 3), e.g. a hemisphere grid) from each
    grid view v_i (``view_dirs`` (V, 3)) -- ``half_row`` of row i, no view interpolation: (T, V, M, 3) float32, what
    the Lafortune fit sees of a half-vector acquisition."""
    T, V, _L, _ = radiance.shape
    M = light_dirs.shape[0]
    out = np.zeros((T, V, M, 3), np.float32)
    for t in prange(T):
        for i in range(V):
            vx, vy, vz = view_dirs[i, 0], view_dirs[i, 1], view_dirs[i, 2]
            for m in range(M):
                lx, ly, lz = light_dirs[m, 0], light_dirs[m, 1], light_dirs[m, 2]
                if lz <= 0.0:
                    continue
                b0, b1, b2, b3, q0, q1, q2, q3 = half_weights(lnx, lny, lx, ly, lz, vx, vy, vz)
                r0, r1, r2, _den = half_row(radiance, valid, t, i, b0, b1, b2, b3, q0, q1, q2, q3)
                out[t, i, m, 0] = r0
                out[t, i, m, 1] = r1
                out[t, i, m, 2] = r2
    return out


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
    directions). For l_z <= 0: 0 from a hemisphere table (L = lt lph), the lower half read at (l_x, l_y, -l_z) from a
    sphere table (L = 2 lt lph; module doc, "Light from below"). r holds the light's |l_z| as f_1 does (radiance per
    unit irradiance). A plain call, not inlined: inlined at the btf tile loop's six call sites it added 20 s to its
    first compilation."""
    below = 0
    if lz <= 0.0:
        below = lt * lph
        if radiance.shape[2] < 2 * below:
            return 0.0, 0.0, 0.0
        lz = -lz
    a0, a1, a2, a3, p0, p1, p2, p3 = grid_weights(vt, vph, vx, vy, vz)
    b0, b1, b2, b3, q0, q1, q2, q3 = grid_weights(lt, lph, lx, ly, lz)
    b0 += below
    b1 += below
    b2 += below
    b3 += below
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
