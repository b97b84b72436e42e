"""Ray casting through a shell map into tiled fibre exemplars (seed 001 §5.1, CPU path; Porumbescu et al. 2005).

``ShellScene`` (namedtuple of arrays, built by ``stages.core.shell.scene.build_shell_scene``):
  shell      ``planes`` (T, 4, 4) outward face planes, ``nbr`` (T, 4) neighbours (-1 boundary),
             ``w2f`` / ``f2w`` (T, 3, 4) affine maps world <-> flat (stages.tile.tetra)
  boundary   ``btri`` (B, 3, 3) boundary faces, ``btet`` (B,), ``bnrm`` (B, 3) outward normals, and a
             BVH over them (``bn_lo``, ``bn_hi``, ``bn_left``, ``bn_right``, ``bn_start``, ``bn_count``,
             ``bprim``; stages.core.geometry.bvh.build_bvh_nodes)
  blocks     ``block_size`` (2,) bw, bh; ``block_map`` (nbu, nbv) int32 exemplar per block (-1 empty;
             indices wrap periodically); ``ex_nblocks`` (K, 2) blocks per exemplar along x, y
  fibres     the wrapped fibre pieces of every exemplar (stages.tile.exemplar.wrap_pieces), as capsule
             segments: ``points``, ``seg_a``, ``seg_r``, ``seg_src`` (exemplar segment id),
             ``seg_srcfiber`` (exemplar fibre id); one SAH BVH per exemplar, nodes concatenated
             (``fn_*``, ``fprim``), exemplar k's root at ``ex_root[k]``; the same trees 4-wide
             (``fw_box``, ``fw_child``: stages.core.geometry.bvh "Wide nodes"; root ``ex_wide_root[k]``),
             which the ray queries walk.

``shell_trace(sc, start_tet, o, d, tmin, tmax, ign_fiber, ign_seg, ign_window)`` (unit d; ``shell_intersect``
is its form for primary rays from outside the shell) walks the ray:
 1. the nearest boundary face the ray *enters* (d . n < 0) at t >= t_cur (boundary BVH);
 2. from its tetrahedron, tetrahedron to tetrahedron across shared faces: in each, the exit t is the
    nearest face plane the ray leaves through; the ray piece [t_in, t_out] is mapped into flat space by
    the tetrahedron's affine map (a straight segment there, t linear);
 3. the flat segment is cut at block boundaries (2-D DDA); each block interval is shifted by whole
    exemplar periods into its exemplar (block map) and the exemplar's fibres are intersected for
    flat parameter in (s0, s1): a hit is inside that block, so capsules reaching over block borders
    and the periodic copies (wrap-around) are handled by the wrapped pieces;
 4. the first hit is mapped back: t_world = t_in + (s / L)(t_out - t_in), position o + t d, tangent =
    the linear part of f2w applied to the flat segment direction; leaving the shell through a
    boundary face resumes at 1 (a ray can cross a curved shell several times). A ray that starts inside
    the shell (a scattered or shadow ray leaving a fibre) starts at 2 in the tetrahedron it starts in.
Returns a ``ShellHit`` (t, tet, segment, fibre, exemplar, block_i, block_j, and the 3-tuples hit,
tangent, normal, flat, then radius) with segment / fibre the exemplar's ids, normal the capsule's outward
normal mapped by the inverse transpose of the shell map, flat the hit in the exemplar's own space,
radius the hit capsule's radius in flat space; t = inf and ids -1 on a miss. The queries allocate
nothing (vectors are tuples, the node stack is on the machine stack), so callers compiled without
numba's reference counting (fiberpath on a tiling) can use them.
Skipped fibre segments: every periodic copy of ``ign_fiber`` near ``ign_seg`` (copies lie at least one
exemplar period apart, far beyond a scattering vertex's neighbourhood in practice).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit, prange
from numba.extending import overload

from stages.core.dispatch import is_tuple_class, runtime_value
from stages.core.geometry.bvh import segment_hit
from stages.core.geometry.capsule import capsule_normal
from stages.core.geometry.dda import dda_axis, dda_next
from stages.core.geometry.slab import inverse_direction, slab_enter
from stages.core.geometry.stack import STACK_SIZE, stack_array
from stages.core.geometry.surface import SurfaceHit, answer_surface_queries
from stages.core.geometry.wide_walk import Ray, leaf_test, wide_any, wide_nearest

ShellScene = namedtuple("ShellScene", [
    "planes", "nbr", "w2f", "f2w",
    "btri", "btet", "bnrm", "bn_lo", "bn_hi", "bn_left", "bn_right", "bn_start", "bn_count", "bprim",
    "block_size", "block_map", "ex_nblocks",
    "points", "seg_a", "seg_r", "seg_src", "seg_srcfiber",
    "fn_lo", "fn_hi", "fn_left", "fn_right", "fn_start", "fn_count", "fprim", "ex_root",
    "fw_box", "fw_child", "ex_wide_root"])

ShellHit = namedtuple("ShellHit", ["t", "tet", "segment", "fibre", "exemplar", "block_i", "block_j", "hit",
                                   "tangent", "normal", "flat", "radius"])
ShellHit.__doc__ = """shell_trace's result (module doc): ids int64, t and radius float64, the vectors 3-tuples."""

MAX_STEPS = 1 << 20


@njit(cache=True)
def _box(lo, hi, node, ox, oy, oz, ix, iy, iz, tmin, tmax):
    return slab_enter(lo[node, 0], lo[node, 1], lo[node, 2], hi[node, 0], hi[node, 1], hi[node, 2],
                      ox, oy, oz, ix, iy, iz, tmin, tmax)


@njit(cache=True)
def _tri_hit(tri, ox, oy, oz, dx, dy, dz):
    """Moller-Trumbore, edges inclusive (a ray through a shared edge hits both faces)."""
    ax, ay, az = tri[0, 0], tri[0, 1], tri[0, 2]
    e1x, e1y, e1z = tri[1, 0] - ax, tri[1, 1] - ay, tri[1, 2] - az
    e2x, e2y, e2z = tri[2, 0] - ax, tri[2, 1] - ay, tri[2, 2] - az
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return np.inf
    inv = 1.0 / det
    sx, sy, sz = ox - ax, oy - ay, oz - az
    u = (sx * px + sy * py + sz * pz) * inv
    eps = 1e-9
    if u < -eps or u > 1.0 + eps:
        return np.inf
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < -eps or u + v > 1.0 + eps:
        return np.inf
    return (e2x * qx + e2y * qy + e2z * qz) * inv


@njit(cache=True)
def enter_shell(sc, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """(t, boundary face) of the nearest boundary face entered at tmin <= t < tmax; (inf, -1) if none."""
    if sc.bprim.shape[0] == 0:
        return np.inf, -1
    ix, iy, iz = inverse_direction(dx, dy, dz)
    stack = stack_array(STACK_SIZE, np.int64)
    stack[0] = 0
    sp = 1
    best = tmax
    bi = -1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if _box(sc.bn_lo, sc.bn_hi, node, ox, oy, oz, ix, iy, iz, tmin, best) == np.inf:
            continue
        if sc.bn_left[node] < 0:
            for j in range(sc.bn_start[node], sc.bn_start[node] + sc.bn_count[node]):
                f = sc.bprim[j]
                if sc.bnrm[f, 0] * dx + sc.bnrm[f, 1] * dy + sc.bnrm[f, 2] * dz >= 0.0:
                    continue  # leaving, not entering
                t = _tri_hit(sc.btri[f], ox, oy, oz, dx, dy, dz)
                if t >= tmin and (t < best or (t == best and bi >= 0 and f < bi)):
                    best = t
                    bi = f
            continue
        stack[sp] = sc.bn_left[node]
        stack[sp + 1] = sc.bn_right[node]
        sp += 2
    if bi < 0:
        return np.inf, -1
    return best, bi


@njit(cache=True)
def tet_exit(sc, tet, ox, oy, oz, dx, dy, dz, t_in):
    """(t_out, face) where the ray leaves tetrahedron tet (nearest outward face plane beyond t_in)."""
    best = np.inf
    face = -1
    for i in range(4):
        nx, ny, nz, c = sc.planes[tet, i, 0], sc.planes[tet, i, 1], sc.planes[tet, i, 2], sc.planes[tet, i, 3]
        den = nx * dx + ny * dy + nz * dz
        if den > 0.0:
            t = (c - (nx * ox + ny * oy + nz * oz)) / den
            if t < best:
                best = t
                face = i
    if best < t_in:
        best = t_in
    return best, face


@njit(cache=True, inline="always")
def _skipped(sc, s, ign_fiber, ign_seg, ign_window):
    return ign_fiber >= 0 and sc.seg_srcfiber[s] == ign_fiber and abs(sc.seg_src[s] - ign_seg) <= ign_window


ShellLeaves = namedtuple("ShellLeaves", ["scene", "ign_fiber", "ign_seg", "ign_window"])
ShellLeaves.__doc__ = """A ``ShellScene``'s exemplar leaf entries for ``wide_walk`` (``fprim``: wrapped pieces) and the
pieces the query skips: those of exemplar fibre ``ign_fiber`` within ``ign_window`` of exemplar segment
``ign_seg`` (-1: none)."""


@overload(leaf_test, inline="always")
def _shell_leaf_test(leaves, j, ray, tmin):
    if is_tuple_class(leaves, ShellLeaves):
        def impl(leaves, j, ray, tmin):
            sc = leaves.scene
            s = sc.fprim[j]
            if _skipped(sc, s, leaves.ign_fiber, leaves.ign_seg, leaves.ign_window):
                return s, np.inf
            return s, segment_hit(sc, s, ray.ox, ray.oy, ray.oz, ray.dx, ray.dy, ray.dz, tmin)
        return impl


@njit(cache=True, _nrt=False)
def fiber_nearest(sc, root, ray, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Nearest capsule hit (t, segment) with tmin < t < tmax along ``ray`` (a ``Ray``) in the wide BVH rooted at
    ``root`` (ties: lower index), skipping segments of exemplar fibre ``ign_fiber`` within ``ign_window`` of
    exemplar segment ``ign_seg`` (-1: test everything)."""
    t, s = wide_nearest(sc.fw_box, sc.fw_child, root, ShellLeaves(sc, ign_fiber, ign_seg, ign_window), ray, tmin,
                        tmin, tmax)
    if s < 0:
        return np.inf, -1
    return t, s


@njit(cache=True, _nrt=False)
def fiber_any(sc, root, ray, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Is there a capsule hit with tmin < t < tmax along ``ray`` in the wide BVH rooted at ``root`` (skips as
    ``fiber_nearest``)? Stops at the first one found: shadow rays need no nearest hit."""
    return wide_any(sc.fw_box, sc.fw_child, root, ShellLeaves(sc, ign_fiber, ign_seg, ign_window), ray, tmin, tmin,
                    tmax) >= 0


@njit(cache=True)
def _floor_div(x, w):
    return int(math.floor(x / w))


@njit(cache=True)
def block_walk(sc, ax, ay, az, ux, uy, uz, L, ign_fiber, ign_seg, ign_window, any_hit):
    """The block walk of the flat segment a + s u, 0 < s < L (u unit), through the block map, meeting
    each block's exemplar BVH: the nearest fibre hit (``fiber_nearest``), or with ``any_hit`` the first
    one found (``fiber_any``; then the returned segment is 0 and the distance and point are not set).
    Returns (s, wrapped segment, exemplar, block i, block j, flat hit in exemplar space x, y, z); the
    segment is -1 where nothing is met."""
    bw = sc.block_size[0]
    bh = sc.block_size[1]
    nbu = sc.block_map.shape[0]
    nbv = sc.block_map.shape[1]
    i = _floor_div(ax, bw)
    j = _floor_div(ay, bh)
    stx, tmx, tdx = dda_axis(i * bw, (i + 1) * bw, bw, ax, ux)
    sty, tmy, tdy = dda_axis(j * bh, (j + 1) * bh, bh, ay, uy)
    s = 0.0
    steps = 0
    while s < L and steps < MAX_STEPS:
        steps += 1
        s1 = min(tmx, tmy, L)
        if s1 > s:
            k = sc.block_map[i % nbu, j % nbv]
            if k >= 0:
                nx = sc.ex_nblocks[k, 0]
                ny = sc.ex_nblocks[k, 1]
                shx = (i - (i % nx)) * bw
                shy = (j - (j % ny)) * bh
                ray = Ray(ax - shx, ay - shy, az, ux, uy, uz)
                if any_hit:
                    if fiber_any(sc, sc.ex_wide_root[k], ray, s, s1, ign_fiber, ign_seg, ign_window):
                        return s, 0, k, i, j, 0.0, 0.0, 0.0
                else:
                    t, seg = fiber_nearest(sc, sc.ex_wide_root[k], ray, s, s1, ign_fiber, ign_seg, ign_window)
                    if seg >= 0:
                        return t, seg, k, i, j, ax - shx + t * ux, ay - shy + t * uy, az + t * uz
            s = s1
        i, j, tmx, tmy = dda_next(i, j, tmx, tmy, stx, sty, tdx, tdy)
        if tmx == np.inf and tmy == np.inf:
            break
    return np.inf, -1, -1, 0, 0, 0.0, 0.0, 0.0


@njit(cache=True)
def flat_segment_hit(sc, ax, ay, az, ux, uy, uz, L, ign_fiber, ign_seg, ign_window):
    """First fibre hit along the flat segment a + s u, 0 < s < L (u unit), through the block map.
    Returns (s, wrapped segment, exemplar, block i, block j, flat hit in exemplar space x, y, z)."""
    return block_walk(sc, ax, ay, az, ux, uy, uz, L, ign_fiber, ign_seg, ign_window, False)


@njit(cache=True)
def flat_segment_occluded(sc, ax, ay, az, ux, uy, uz, L, ign_fiber, ign_seg, ign_window):
    """Does the flat segment a + s u, 0 < s < L (u unit), meet any fibre (``block_walk`` with
    ``fiber_any``)?"""
    return block_walk(sc, ax, ay, az, ux, uy, uz, L, ign_fiber, ign_seg, ign_window, True)[1] >= 0


@njit(cache=True)
def shell_trace(sc, start_tet, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """The general query (see the module doc): a ray starting inside tetrahedron ``start_tet`` (-1: outside
    the shell) at t = tmin; fibre segments of ``ign_fiber`` near ``ign_seg`` skipped. Returns a
    ``ShellHit``.
    13 parameters: the surface-scene interface's (``stages.core.geometry.surface``: scene, start cell, ray, window,
    skipped fibre, segment and window), shared by every scene class and its callers."""
    zero = (0.0, 0.0, 0.0)
    tcur = tmin
    w2f = sc.w2f
    tet = start_tet
    for _entry in range(4096):
        if tet < 0:
            tb, f = enter_shell(sc, ox, oy, oz, dx, dy, dz, tcur, tmax)
            if f < 0:
                break
            tet = sc.btet[f]
            t_in = tb
        else:
            t_in = tcur
        for _step in range(MAX_STEPS):
            t_out, face = tet_exit(sc, tet, ox, oy, oz, dx, dy, dz, t_in)
            if face < 0:
                t_out = t_in
            t_end = min(t_out, tmax)
            if t_end > t_in:
                px, py, pz = ox + t_in * dx, oy + t_in * dy, oz + t_in * dz
                qx, qy, qz = ox + t_end * dx, oy + t_end * dy, oz + t_end * dz
                ax = w2f[tet, 0, 0] * px + w2f[tet, 0, 1] * py + w2f[tet, 0, 2] * pz + w2f[tet, 0, 3]
                ay = w2f[tet, 1, 0] * px + w2f[tet, 1, 1] * py + w2f[tet, 1, 2] * pz + w2f[tet, 1, 3]
                az = w2f[tet, 2, 0] * px + w2f[tet, 2, 1] * py + w2f[tet, 2, 2] * pz + w2f[tet, 2, 3]
                bx = w2f[tet, 0, 0] * qx + w2f[tet, 0, 1] * qy + w2f[tet, 0, 2] * qz + w2f[tet, 0, 3]
                by = w2f[tet, 1, 0] * qx + w2f[tet, 1, 1] * qy + w2f[tet, 1, 2] * qz + w2f[tet, 1, 3]
                bz = w2f[tet, 2, 0] * qx + w2f[tet, 2, 1] * qy + w2f[tet, 2, 2] * qz + w2f[tet, 2, 3]
                ex, ey, ez = bx - ax, by - ay, bz - az
                L = math.sqrt(ex * ex + ey * ey + ez * ez)
                if L > 0.0:
                    s, seg, k, bi, bj, fx, fy, fz = flat_segment_hit(sc, ax, ay, az, ex / L, ey / L, ez / L, L,
                                                                     ign_fiber, ign_seg, ign_window)
                    if seg >= 0:
                        t = t_in + (s / L) * (t_end - t_in)
                        hit = (ox + t * dx, oy + t * dy, oz + t * dz)
                        a = sc.seg_a[seg]
                        P = sc.points
                        vx, vy, vz = P[a + 1, 0] - P[a, 0], P[a + 1, 1] - P[a, 1], P[a + 1, 2] - P[a, 2]
                        f2w = sc.f2w
                        wx = f2w[tet, 0, 0] * vx + f2w[tet, 0, 1] * vy + f2w[tet, 0, 2] * vz
                        wy = f2w[tet, 1, 0] * vx + f2w[tet, 1, 1] * vy + f2w[tet, 1, 2] * vz
                        wz = f2w[tet, 2, 0] * vx + f2w[tet, 2, 1] * vy + f2w[tet, 2, 2] * vz
                        n = math.sqrt(wx * wx + wy * wy + wz * wz)
                        tan = (wx / n, wy / n, wz / n) if n > 0.0 else zero
                        # capsule normal in flat space, carried by the inverse transpose (w2f^T)
                        nfx, nfy, nfz, _u = capsule_normal(fx, fy, fz, P[a, 0], P[a, 1], P[a, 2],
                                                           P[a + 1, 0], P[a + 1, 1], P[a + 1, 2])
                        mx = w2f[tet, 0, 0] * nfx + w2f[tet, 1, 0] * nfy + w2f[tet, 2, 0] * nfz
                        my = w2f[tet, 0, 1] * nfx + w2f[tet, 1, 1] * nfy + w2f[tet, 2, 1] * nfz
                        mz = w2f[tet, 0, 2] * nfx + w2f[tet, 1, 2] * nfy + w2f[tet, 2, 2] * nfz
                        n = math.sqrt(mx * mx + my * my + mz * mz)
                        nrm = (mx / n, my / n, mz / n) if n > 0.0 else zero
                        return ShellHit(t, np.int64(tet), np.int64(sc.seg_src[seg]), np.int64(sc.seg_srcfiber[seg]),
                                        np.int64(k), np.int64(bi), np.int64(bj), hit, tan, nrm, (fx, fy, fz),
                                        np.float64(sc.seg_r[seg]))
            if t_end >= tmax:
                return ShellHit(np.inf, -1, -1, -1, -1, 0, 0, zero, zero, zero, zero, 0.0)
            nb = sc.nbr[tet, face] if face >= 0 else -1
            if nb < 0:
                tcur = t_out
                tet = -1
                break
            tet = nb
            t_in = t_out
    return ShellHit(np.inf, -1, -1, -1, -1, 0, 0, zero, zero, zero, zero, 0.0)


@njit(cache=True)
def shell_intersect(sc, ox, oy, oz, dx, dy, dz, tmax):
    """Primary rays (origin outside the shell): the ``ShellHit`` of shell_trace from t = 0."""
    return shell_trace(sc, runtime_value(-1), ox, oy, oz, dx, dy, dz, 0.0, tmax, runtime_value(-1), runtime_value(-1),
                       runtime_value(0))


@njit(cache=True, parallel=True)
def trace_primary(sc, cam_o, dirs, tmax):
    """Primary hits for a batch of unit directions (R, 3) from one origin: t (R,), segment (R,),
    exemplar (R,), tet (R,), world tangents (R, 3)."""
    R = dirs.shape[0]
    t_out = np.full(R, np.inf)
    seg = np.full(R, -1, np.int64)
    ex = np.full(R, -1, np.int64)
    tets = np.full(R, -1, np.int64)
    tan = np.zeros((R, 3))
    for r in prange(R):
        h = shell_intersect(sc, cam_o[0], cam_o[1], cam_o[2], dirs[r, 0], dirs[r, 1], dirs[r, 2], tmax)
        t_out[r] = h.t
        seg[r] = h.segment
        ex[r] = h.exemplar
        tets[r] = h.tet
        tan[r, 0], tan[r, 1], tan[r, 2] = h.tangent[0], h.tangent[1], h.tangent[2]
    return t_out, seg, ex, tets, tan


# ------------------------------------------------------------------------------------------------
# the surface-scene interface (stages.core.geometry.surface) for a ShellScene
@njit(cache=True)
def shell_surface_hit(sc, cell, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window):
    """``surface_hit`` for a ``ShellScene``: ``shell_trace``'s hit as a ``SurfaceHit``. 13 parameters: the
    surface-scene interface's, which it answers for a ``ShellScene``."""
    h = shell_trace(sc, cell, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window)
    tan = h.tangent
    nrm = h.normal
    return SurfaceHit(h.t, h.segment, h.fibre, h.tet, tan[0], tan[1], tan[2], nrm[0], nrm[1], nrm[2], h.radius)


@njit(cache=True)
def shell_surface_occluded(sc, cell, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window):
    """``surface_occluded`` for a ``ShellScene``: does ``shell_trace`` find a hit? 13 parameters: the
    surface-scene interface's, which it answers for a ``ShellScene``."""
    return shell_trace(sc, cell, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window).t < np.inf


answer_surface_queries(ShellScene, shell_surface_hit, shell_surface_occluded, with_cell=True)
