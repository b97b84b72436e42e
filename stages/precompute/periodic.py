"""Rays through the flat fabric made of one exemplar repeated without end (seed 001 §4.1-§4.2).

Seed 001 precomputes on "a large, flat section of fabric synthesized in the same way as the material
to be rendered"; loomlight uses its limit, the exemplar repeated without end in x and y, so no ray
ever leaves through a side and every segment sees the same surroundings as its copies in the middle
of the cloth. Exemplar space (``stages.tile.exemplar``): x in [0, W), y in [0, H), z up; the fabric
occupies the slab z_lo <= z <= z_hi (the exemplar's fibre bounds).

``periodic_scene(sc, k)`` is the ``ShellScene`` (``stages.core.shell.traversal``) of a tiling whose
block map holds exemplar ``k`` alone, one period of blocks: the block walk of
``flat_segment_hit`` then wraps every block into exemplar k, i.e. it meets the exemplar's wrapped
fibre pieces in every periodic copy. ``periodic_hit`` casts a ray from a point of exemplar space
until it leaves the slab (or has run ``max_dist``), skipping the fibre ``ign_fiber`` (and its periodic
copies: a periodic exemplar's fibre continues in its copies, so the copies are the same fibre).

Returns a ``PeriodicHit``: t (inf on escape), the exemplar segment and fibre hit (global ids of the
tiling: ``seg_src`` / ``seg_srcfiber``), the wrapped segment (for its tangent and radius), the hit
point (in the ray's own coordinates, not wrapped), the unit tangent of the hit segment and the hit in
the exemplar's own box (the wrapped piece's coordinates: the hit point less whole periods).

Rays from a segment (``ray_start``, ``periodic_hit_outside``): the SVF and the IIRTF are defined at
mu_k, the centre of a fibre segment (§4.1, §4.2), standing in for the segment's surface. The
procedural fibres overlap (half a ply's cross-section is fibre, placed, not packed:
``stages.core.geometry.capsule``), which the paper's fibres (CT scans) do not:

- about half the damask's midpoints lie inside another fibre's capsule; a ray from there meets that
  capsule at its way out, and such a segment would see nothing at all (60 % of the damask's segments,
  measured), although its surface outside the covering fibre is lit and seen by the path tracer (a
  camera ray never reaches a point inside a capsule: it hits the covering capsule first). So rays from
  a point pass through the capsules that contain it and stop at the first capsule they *enter*;
- a fibre passing through the segment's own capsule, without containing the midpoint, still stops a
  ray from the midpoint before it leaves the segment: light from that direction that reaches the
  segment's surface is counted as blocked (on the tests' flat swatch, 10-11 % of the camera samples
  lit in fiberpath were shadowed at the midpoint, three quarters of them by a fibre passing within a
  fraction of a radius). So the SVF's ray in direction d starts where it leaves the segment's capsule
  (``ray_start``): on the side of the segment facing d, where light from d arrives. Measured
  (``make prt-sweep``, single scattering against fiberpath at depth 1): relative RMSE of mean intensity
  3.3 / 8.1 / 7.5 % from the midpoint, 2.0 / 3.7 / 5.5 % from the surface (the two satin patches and
  the draped damask).
- The IIRTF's paths start at the midpoint and use ``periodic_hit`` itself: a capsule that contains
  mu_k is met at its way out, as fiberpath's rays meet a capsule they start in. Those are the fibres in
  contact with the segment, the ones that pass it the most twice-scattered light; passing through them
  (as the SVF's rays do) left multiple scattering low in every configuration, most in the lowest-albedo
  channel, and the whole prt picture's relative RMSE of mean intensity at 8.8 / 7.6 / 7.4 % against
  5.7 / 4.4 / 4.5 % now (``make prt-sweep``, 2026-12-02). Started on the segment's surface instead, it
  came out darker still (11.5 / 10.9 / 5.9 % -> 15.0 / 12.2 / 8.3 % in multiple scattering alone,
  measured with the pass-through rule).

Paths through the periodic fabric (``periodic_path``): the IIRTF's transfer paths and the BTF
acquisition's camera paths are one path tracer -- vertex set-up, next-event estimation, material
sampling with Russian roulette (``stages.core.sampling.continue_path``), the next ray -- that differ
only in which light directions a vertex is lit from and what an escape adds. Those two are a *tally*'s,
a namedtuple each precompute defines (``IirtfLight``, ``BtfLights``) and answers ``light_vertex`` and
``path_escaped`` for (``register_tally``: ``numba.extending.overload``, as ``stages.core.dispatch``
describes), so the loop is written once and compiled once per tally.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class, runtime_value
from stages.core.geometry.capsule import INSIDE, capsule_intersect, capsule_normal, point_segment_dist2
from stages.core.sampling import continue_path
from stages.core.shading.material import material_is_curve, material_prepare
from stages.core.shell.traversal import flat_segment_hit, flat_segment_occluded

WHOLE_FIBRE = 1 << 30   # a skip window longer than any fibre: ``ign_fiber`` is skipped whole

PeriodicHit = namedtuple("PeriodicHit", ["t", "segment", "fibre", "wrapped", "x", "y", "z", "tx", "ty", "tz",
                                         "fx", "fy", "fz"])
PeriodicHit.__doc__ = "periodic_hit's result (module doc); t = inf and ids -1 on escape."

PeriodicPaths = namedtuple("PeriodicPaths", ["scene", "z_lo", "z_hi", "W", "H", "mat_of_fiber", "mats", "max_depth",
                                             "rr_depth", "max_dist", "eps"])
PeriodicPaths.__doc__ = """The periodic fabric a precompute's paths walk and how far they go: ``scene``
(``periodic_scene``), its slab z_lo..z_hi and period W x H, the fibres' material rows (``mat_of_fiber``,
``mats``), at most ``max_depth`` scattering events with Russian roulette from ``rr_depth``, rays at most
``max_dist`` long offset by ``eps``. The IIRTF's and the BTF acquisition's path tracers take it whole."""


def periodic_scene(sc, k: int):
    """``sc`` with a block map of exemplar ``k`` alone (one period of its blocks)."""
    nx, ny = (int(v) for v in sc.ex_nblocks[k])
    return sc._replace(block_map=np.full((nx, ny), k, np.int32))


@njit(cache=True)
def slab_length(oz, dz, z_lo, z_hi, max_dist):
    """Distance along unit d from height oz to where the ray leaves the slab, capped at max_dist."""
    if dz > 0.0:
        L = (z_hi - oz) / dz
    elif dz < 0.0:
        L = (z_lo - oz) / dz
    else:
        L = np.inf
    return min(max(L, 0.0), max_dist)


@njit(cache=True)
def periodic_hit(sc, z_lo, z_hi, ox, oy, oz, dx, dy, dz, ign_fiber, max_dist):
    """First fibre hit of the ray o + t d (unit d), 0 < t, in the periodic fabric of ``sc`` (a
    ``periodic_scene``); the whole fibre ``ign_fiber`` is skipped (-1: none)."""
    L = slab_length(oz, dz, z_lo, z_hi, max_dist)
    if L <= 0.0:
        return PeriodicHit(np.inf, -1, -1, -1, ox, oy, oz, 0.0, 0.0, 0.0, ox, oy, oz)
    t, w, _k, _i, _j, fx, fy, fz = flat_segment_hit(sc, ox, oy, oz, dx, dy, dz, L, ign_fiber, runtime_value(0),
                                                    runtime_value(WHOLE_FIBRE))
    if w < 0:
        return PeriodicHit(np.inf, -1, -1, -1, ox, oy, oz, 0.0, 0.0, 0.0, ox, oy, oz)
    a = sc.seg_a[w]
    P = sc.points
    tx = P[a + 1, 0] - P[a, 0]
    ty = P[a + 1, 1] - P[a, 1]
    tz = P[a + 1, 2] - P[a, 2]
    n = math.sqrt(tx * tx + ty * ty + tz * tz)
    if n > 0.0:
        tx /= n
        ty /= n
        tz /= n
    return PeriodicHit(t, sc.seg_src[w], sc.seg_srcfiber[w], w, ox + t * dx, oy + t * dy, oz + t * dz, tx, ty, tz,
                       fx, fy, fz)


@njit(cache=True)
def periodic_occluded(sc, z_lo, z_hi, ox, oy, oz, dx, dy, dz, ign_fiber, max_dist):
    """Does the ray o + t d (unit d), 0 < t, meet a fibre before it leaves the slab (or has run
    ``max_dist``)? ``periodic_hit``'s answer to "is t finite", without looking for the nearest hit."""
    L = slab_length(oz, dz, z_lo, z_hi, max_dist)
    if L <= 0.0:
        return False
    return flat_segment_occluded(sc, ox, oy, oz, dx, dy, dz, L, ign_fiber, runtime_value(0),
                                 runtime_value(WHOLE_FIBRE))


@njit(cache=True)
def contains(sc, w, px, py, pz):
    """Is the point p (the wrapped piece's coordinates) inside wrapped capsule w?"""
    a = sc.seg_a[w]
    P = sc.points
    r = sc.seg_r[w]
    return point_segment_dist2(px, py, pz, P[a, 0], P[a, 1], P[a, 2], P[a + 1, 0], P[a + 1, 1], P[a + 1, 2]) \
        < INSIDE * r * r


@njit(cache=True)
def ray_start(mx, my, mz, capsule, dx, dy, dz):
    """(x, y, z, t): where a ray from segment midpoint m in direction d starts, t along d from m. With
    the segment's capsule (a, b, r; r > 0), where the ray leaves it: the side of the segment that faces
    d, which is where light from d arrives (module doc, *Rays from a segment*); with r = 0 (no capsule),
    m itself."""
    t = 0.0
    if capsule[6] > 0.0:
        t = capsule_intersect(mx, my, mz, dx, dy, dz, capsule[0], capsule[1], capsule[2],
                              capsule[3], capsule[4], capsule[5], capsule[6], 0.0)
        if not (t > 0.0 and t < np.inf):
            t = 0.0
    return mx + t * dx, my + t * dy, mz + t * dz, t


@njit(cache=True)
def periodic_hit_outside(sc, z_lo, z_hi, ox, oy, oz, dx, dy, dz, ign_fiber, max_dist):
    """``periodic_hit`` for a ray from a segment's midpoint: capsules that contain the origin let it
    through (module doc); t counts from the origin."""
    t0 = 0.0
    x, y, z = ox, oy, oz
    for _ in range(256):
        h = periodic_hit(sc, z_lo, z_hi, x, y, z, dx, dy, dz, ign_fiber, max_dist - t0)
        if math.isinf(h.t):
            return h
        # the origin in the hit piece's coordinates: the same shift as the hit point's
        sx = (x + h.t * dx) - h.fx
        sy = (y + h.t * dy) - h.fy
        if not contains(sc, h.wrapped, ox - sx, oy - sy, oz):
            return PeriodicHit(t0 + h.t, h.segment, h.fibre, h.wrapped, h.x, h.y, h.z, h.tx, h.ty, h.tz,
                               h.fx, h.fy, h.fz)
        t0 += h.t
        x, y, z = h.x, h.y, h.z     # the way out of a covering capsule: on its surface, so not inside it
        if t0 >= max_dist:
            break
    return PeriodicHit(np.inf, -1, -1, -1, ox, oy, oz, 0.0, 0.0, 0.0, ox, oy, oz)


@njit(cache=True)
def wrap_into_period(x, y, W, H):
    """(x, y) moved by whole periods into [0, W) x [0, H) (keeps path vertices near the origin)."""
    return x - W * math.floor(x / W), y - H * math.floor(y / H)


@njit(cache=True)
def periodic_vertex(sc, mats, mat_of_fiber, h, W, H, eps, t_tan, n, so):
    """Set up the scattering vertex of hit ``h`` for a path tracer in the periodic fabric: its tangent
    ``t_tan``, normal ``n`` (zero for a curve material: the BCSDF integrates over the fibre's cross-section;
    the capsule's outward normal for an opaque one) and where rays leave from (``so``, wrapped into the
    period); returns (material row, fibre that rays leaving it skip, -1 for an opaque surface)."""
    row = mat_of_fiber[h.fibre]
    x, y = wrap_into_period(h.x, h.y, W, H)
    t_tan[0] = h.tx
    t_tan[1] = h.ty
    t_tan[2] = h.tz
    if material_is_curve(mats[row]):
        n[0] = 0.0
        n[1] = 0.0
        n[2] = 0.0
        so[0] = x
        so[1] = y
        so[2] = h.z
        return row, h.fibre
    # opaque surface: the capsule's outward normal (the hit moved to the copy of its wrapped piece)
    a = sc.seg_a[h.wrapped]
    P = sc.points
    dx = x - P[a, 0]
    dy = y - P[a, 1]
    dx -= W * math.floor(dx / W + 0.5)
    dy -= H * math.floor(dy / H + 0.5)
    nx, ny, nz, _s = capsule_normal(P[a, 0] + dx, P[a, 1] + dy, h.z, P[a, 0], P[a, 1], P[a, 2],
                                    P[a + 1, 0], P[a + 1, 1], P[a + 1, 2])
    n[0] = nx
    n[1] = ny
    n[2] = nz
    off = 1e-3 * sc.seg_r[h.wrapped] + eps
    so[0] = x + off * nx
    so[1] = y + off * ny
    so[2] = h.z + off * nz
    return row, -1


# ------------------------------------------------------------------------------------------------
# the path tracer the IIRTF and the BTF acquisition share

PathScratch = namedtuple("PathScratch", ["t_tan", "n", "so", "wi", "wo", "wl", "ctx"])
PathScratch.__doc__ = """The vectors a periodic path works in, allocated by its caller (on the heap or the machine
stack): the vertex's tangent ``t_tan``, normal ``n`` and ray origin ``so`` (``periodic_vertex``), the direction
towards where the path came from ``wi`` (the caller sets it for the first vertex), the sampled next direction
``wo``, a light direction ``wl`` and the material context ``ctx`` (``CTX_SIZE``), all float64."""


def light_vertex(tally, paths, v, mat, nf, tp, seed, key, base):
    """Next-event estimation at a vertex of a periodic path (``periodic_path``): for each light direction
    the tally takes, the vertex's f(wi, wl) times the throughput ``tp`` (r, g, b) where the shadow ray
    from ``v.so`` (skipping fibre ``nf``) leaves the fabric, added to what the tally records; returns the
    number of shadow rays cast. Random dimensions from ``base + DIRECTION_DIMS`` are the tally's. numba-only:
    each tally class (``stages.precompute.iirtf``, ``stages.precompute.btf``) overloads it (``register_tally``)."""
    raise TypeError("light_vertex is only callable from numba-compiled code")


def path_escaped(tally, wo, tp, pdf):
    """The path left the fabric along ``wo`` (sampled from the last vertex's material with density
    ``pdf``) with throughput ``tp``: what the tally adds for the light it meets there. numba-only
    (overloaded per tally class)."""
    raise TypeError("path_escaped is only callable from numba-compiled code")


def register_tally(cls, vertex, escaped=None):
    """Overloads ``light_vertex`` and ``path_escaped`` for tallies of namedtuple class ``cls`` with the kernels
    ``vertex`` and ``escaped`` (same arguments); ``escaped`` None: an escape adds nothing."""
    @overload(light_vertex)
    def _light_vertex(tally, paths, v, mat, nf, tp, seed, key, base):
        if is_tuple_class(tally, cls):
            return lambda tally, paths, v, mat, nf, tp, seed, key, base: vertex(
                tally, paths, v, mat, nf, tp, seed, key, base)

    @overload(path_escaped)
    def _path_escaped(tally, wo, tp, pdf):
        if is_tuple_class(tally, cls):
            if escaped is None:
                return lambda tally, wo, tp, pdf: None
            return lambda tally, wo, tp, pdf: escaped(tally, wo, tp, pdf)


@njit(cache=True)
def light_reaches(paths, v, nf):
    """Does the shadow ray from the vertex (``v.so``) along its light direction ``v.wl``, skipping fibre ``nf``,
    leave the fabric? The one visibility test of every tally's ``light_vertex``."""
    so = v.so
    wl = v.wl
    return not periodic_occluded(paths.scene, paths.z_lo, paths.z_hi, so[0], so[1], so[2], wl[0], wl[1], wl[2], nf,
                                 paths.max_dist)


DIRECTION_DIMS = 4   # per vertex: three uniforms for the sampled direction, one for Russian roulette


@njit(cache=True, _nrt=False)
def periodic_path(paths, tally, v, h, seed, key, dim0, dims_per_vertex):
    """The path from its first hit ``h`` (coming from ``-v.wi``) through the periodic fabric of ``paths``
    (a ``PeriodicPaths``), one vertex after another until it leaves the fabric, Russian roulette ends it
    or it has ``max_depth`` vertices; returns the rays cast after the first. At each vertex, in order:

    - the vertex: its material row, tangent, normal and where rays leave from (``periodic_vertex``);
    - emitter sampling: ``light_vertex(tally, ...)``, next-event estimation for the tally's lights;
    - material sampling and roulette: ``continue_path`` with the vertex's uniforms ``base`` .. ``base + 3``
      (base = dim0 + dims_per_vertex (depth - 1); a tally that draws its own takes the dimensions after
      those, dims_per_vertex > DIRECTION_DIMS);
    - the next ray: a hit is the next vertex, an escape is ``path_escaped(tally, ...)`` and the end.

    Compiled without reference counting: the BTF acquisition's threads walk the same arrays for every ray."""
    sc = paths.scene
    mats = paths.mats
    t_tan = v.t_tan
    n = v.n
    so = v.so
    wi = v.wi
    wo = v.wo
    ctx = v.ctx
    tp = (1.0, 1.0, 1.0)   # the path's throughput (r, g, b)
    rays = 0
    depth = 1
    while True:
        # the vertex
        row, nf = periodic_vertex(sc, mats, paths.mat_of_fiber, h, paths.W, paths.H, paths.eps, t_tan, n, so)
        mat = mats[row]
        material_prepare(mat, t_tan, n, wi, ctx)
        base = dim0 + dims_per_vertex * (depth - 1)
        # emitter sampling
        rays += light_vertex(tally, paths, v, mat, nf, tp, seed, key, base)
        if depth >= paths.max_depth:
            break
        # material sampling and Russian roulette
        step = continue_path(mat, ctx, t_tan, n, wi, depth >= paths.rr_depth, seed, key, base, tp, wo)
        if not step.alive:
            break
        tp = step.tp
        # the next ray
        rays += 1
        h = periodic_hit(sc, paths.z_lo, paths.z_hi, so[0], so[1], so[2], wo[0], wo[1], wo[2], nf, paths.max_dist)
        if math.isinf(h.t):
            path_escaped(tally, wo, tp, step.pdf)
            break
        wi[0] = -wo[0]
        wi[1] = -wo[1]
        wi[2] = -wo[2]
        depth += 1
    return rays
