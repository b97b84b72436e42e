"""Voxel-grid density source (``--source grid``) and the voxelizer that builds it from any source.

Grid conventions follow Mitsuba 3's ``gridvolume``: arrays are indexed (z, y, x) and cover the box
[lo, hi]; voxel (i, j, k) has its centre at lo + ((k, j, i) + 0.5) / (NX, NY, NZ) * (hi - lo).
Density is trilinear between voxel centres and clamped at the border (the outermost half voxel
repeats the border value); outside the box the density is zero. Direction, albedo and roughness are
taken from the corner voxel of the interpolation stencil with the largest weight x density (they
are per-fibre quantities and do not average meaningfully across yarns).

GridMedium fields: lo, hi (float64[3]); density (Z, Y, X) float32; direction (Z, Y, X, 3) float32
(unit mean fibre direction, sign arbitrary); albedo (Z, Y, X, 3) float32; roughness (Z, Y, X) float32.

``voxelize(med, lo, hi, res, ss, z0, z1, density, direction, albedo, roughness)`` fills slices
z0..z1-1 of those arrays from any density source by averaging ss^3 stratified point lookups per
voxel: density = mean den; direction = principal eigenvector of the density-weighted orientation
tensor sum(den t t^T) (sign-free, so opposite tangents reinforce); albedo and roughness =
density-weighted means.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.render.media.medium import NO_MEDIUM, MediumPoint, medium_lookup, outside_box, register_medium

GridMedium = namedtuple("GridMedium", ["lo", "hi", "density", "direction", "albedo", "roughness"])


@njit(cache=True)
def grid_lookup(med, x, y, z):
    lo = med.lo
    hi = med.hi
    if outside_box(lo, hi, x, y, z):
        return NO_MEDIUM
    nz, ny, nx = med.density.shape
    ux = (x - lo[0]) / (hi[0] - lo[0]) * nx - 0.5
    uy = (y - lo[1]) / (hi[1] - lo[1]) * ny - 0.5
    uz = (z - lo[2]) / (hi[2] - lo[2]) * nz - 0.5
    fx = math.floor(ux)
    fy = math.floor(uy)
    fz = math.floor(uz)
    ax = ux - fx
    ay = uy - fy
    az = uz - fz
    ix = int(fx)
    iy = int(fy)
    iz = int(fz)
    den = 0.0
    best = -1.0
    bx = 0
    by = 0
    bz = 0
    for c in range(8):
        dx = c & 1
        dy = (c >> 1) & 1
        dz = (c >> 2) & 1
        jx = min(max(ix + dx, 0), nx - 1)
        jy = min(max(iy + dy, 0), ny - 1)
        jz = min(max(iz + dz, 0), nz - 1)
        w = (ax if dx else 1.0 - ax) * (ay if dy else 1.0 - ay) * (az if dz else 1.0 - az)
        v = w * med.density[jz, jy, jx]
        den += v
        if v > best:
            best = v
            bx = jx
            by = jy
            bz = jz
    if den <= 0.0:
        return NO_MEDIUM
    d = med.direction[bz, by, bx]
    a = med.albedo[bz, by, bx]
    # the stored arrays may be float32: every field is float64 (MediumPoint)
    return MediumPoint(np.float64(den), np.float64(d[0]), np.float64(d[1]), np.float64(d[2]), np.float64(a[0]),
                       np.float64(a[1]), np.float64(a[2]), np.float64(med.roughness[bz, by, bx]), np.int64(-1),
                       np.int64(-1))


register_medium(GridMedium, grid_lookup, knows_fibres=False)   # voxels know no fibres


@njit(cache=True)
def _principal_axis(m00, m11, m22, m01, m02, m12, gx, gy, gz):
    """Unit principal eigenvector of a symmetric PSD 3x3 matrix by power iteration from (g)."""
    vx, vy, vz = gx, gy, gz
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    if n == 0.0:
        vx, vy, vz, n = 0.0, 0.0, 1.0, 1.0
    vx /= n
    vy /= n
    vz /= n
    for _ in range(64):
        wx = m00 * vx + m01 * vy + m02 * vz
        wy = m01 * vx + m11 * vy + m12 * vz
        wz = m02 * vx + m12 * vy + m22 * vz
        n = math.sqrt(wx * wx + wy * wy + wz * wz)
        if n == 0.0:
            break
        vx = wx / n
        vy = wy / n
        vz = wz / n
    return vx, vy, vz


def voxelize(med, lo, hi, res, ss, z0, z1, density, direction, albedo, roughness, threads=None):
    """Fill voxel slices z0..z1-1 (local index 0..z1-z0-1 of the output arrays) from ``med``, one
    GIL-free numba call per slice on ``threads`` threads (default: numba's thread count); slices
    write disjoint voxels, so the result does not depend on the thread count."""
    import numba

    n = int(threads or numba.get_num_threads())
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    res = np.asarray(res, np.int64)

    def one(iz):
        voxelize_slice(med, lo, hi, res, int(ss), iz, iz - z0, density, direction, albedo, roughness)

    if n <= 1 or z1 - z0 <= 1:
        for iz in range(z0, z1):
            one(iz)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n) as ex:
        list(ex.map(one, range(z0, z1)))


@njit(cache=True, nogil=True)
def voxelize_slice(med, lo, hi, res, ss, iz, lz, density, direction, albedo, roughness):
    """Voxels of grid slice iz into local slice lz of the output arrays."""
    nx, ny, nz = res[0], res[1], res[2]
    cx = (hi[0] - lo[0]) / nx
    cy = (hi[1] - lo[1]) / ny
    cz = (hi[2] - lo[2]) / nz
    inv = 1.0 / (ss * ss * ss)
    for iy in range(ny):
        for ix in range(nx):
            sd = 0.0
            m00 = 0.0
            m11 = 0.0
            m22 = 0.0
            m01 = 0.0
            m02 = 0.0
            m12 = 0.0
            gx = 0.0
            gy = 0.0
            gz = 0.0
            sr = 0.0
            sg = 0.0
            sb = 0.0
            sro = 0.0
            for a in range(ss):
                for b in range(ss):
                    for c in range(ss):
                        x = lo[0] + (ix + (a + 0.5) / ss) * cx
                        y = lo[1] + (iy + (b + 0.5) / ss) * cy
                        z = lo[2] + (iz + (c + 0.5) / ss) * cz
                        m = medium_lookup(med, x, y, z, -1)
                        den = m.den
                        if den <= 0.0:
                            continue
                        tx, ty, tz = m.tx, m.ty, m.tz
                        sd += den
                        m00 += den * tx * tx
                        m11 += den * ty * ty
                        m22 += den * tz * tz
                        m01 += den * tx * ty
                        m02 += den * tx * tz
                        m12 += den * ty * tz
                        # sign-aligned sum as the power iteration's start vector
                        if tx * gx + ty * gy + tz * gz < 0.0:
                            gx -= den * tx
                            gy -= den * ty
                            gz -= den * tz
                        else:
                            gx += den * tx
                            gy += den * ty
                            gz += den * tz
                        sr += den * m.albedo_r
                        sg += den * m.albedo_g
                        sb += den * m.albedo_b
                        sro += den * m.roughness
            density[lz, iy, ix] = sd * inv
            if sd > 0.0:
                vx, vy, vz = _principal_axis(m00, m11, m22, m01, m02, m12, gx, gy, gz)
                direction[lz, iy, ix, 0] = vx
                direction[lz, iy, ix, 1] = vy
                direction[lz, iy, ix, 2] = vz
                albedo[lz, iy, ix, 0] = sr / sd
                albedo[lz, iy, ix, 1] = sg / sd
                albedo[lz, iy, ix, 2] = sb / sd
                roughness[lz, iy, ix] = sro / sd
            else:
                direction[lz, iy, ix, 0] = 0.0
                direction[lz, iy, ix, 1] = 0.0
                direction[lz, iy, ix, 2] = 1.0
                albedo[lz, iy, ix, 0] = 0.0
                albedo[lz, iy, ix, 1] = 0.0
                albedo[lz, iy, ix, 2] = 0.0
                roughness[lz, iy, ix] = 1.0


def sggx_volume(direction, roughness):
    """Mitsuba's 6-channel SGGX volume (Sxx, Syy, Szz, Sxy, Sxz, Syz) of the fibre-like S per voxel."""
    t = np.asarray(direction, np.float64)
    k = np.asarray(roughness, np.float64) ** 2 - 1.0
    out = np.empty(t.shape[:-1] + (6,), np.float32)
    out[..., 0] = 1.0 + k * t[..., 0] ** 2
    out[..., 1] = 1.0 + k * t[..., 1] ** 2
    out[..., 2] = 1.0 + k * t[..., 2] ** 2
    out[..., 3] = k * t[..., 0] * t[..., 1]
    out[..., 4] = k * t[..., 0] * t[..., 2]
    out[..., 5] = k * t[..., 1] * t[..., 2]
    return out
