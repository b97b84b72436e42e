"""Acquisition of a repeat's radiance samples for the fitted cloth texture (seed 002 §4).

Seed 002 renders a stitch model "with direct and indirect illumination" for every view and light
direction and reads back, per sampling point of a res x res grid on the top face of the model's
bounding box, the radiance of the surface seen through that point along the view direction (Fig. 2:
the point is *projected* along v, so parallax mixes radiance from different surface points into one
texel, which the fit then explains), an alpha per view from ray casting (super-sampled: a fraction),
and the average normal. loomlight path traces its explicit fibres instead of the paper's hardware
lighting, with the repeat's copies all around it (``stages.precompute.periodic``: the exemplar repeated
without end, so parallax and light from the neighbours are exact):

For texel (iy, ix) of the exemplar's W x H box, view v (the grids of ``stages.core.btf``) and sample
s = 0..spp-1: the point p = ((ix + u0) W / res, (iy + u1) H / res, z_plane) on the texture's plane (u jittered
per sample, the super-sampling of the texel's footprint), the ray through p along -v into the fabric (from where
it enters the slab's top). The paper's plane is the top face (z_plane = z_hi); see "The texture's plane".
It misses (leaves through the bottom): a hole for this sample. It hits: a path from there, the fibre
materials of the renderer (``material_eval_pdf`` / ``material_sample``), and at *every* vertex
next-event estimation towards *every* light direction of the light grid (a shadow ray that must leave
the fabric through the top), so one camera path serves all lights (the paper's "reuse camera paths
across lights" -- the cost driver). Each light is directional with unit irradiance, so the sum over the
path's vertices of throughput x f cos x visibility is r(l, v): the radiance per unit irradiance that
the fit's f_r(l, v) models (``stages.core.btf``). Russian roulette from ``rr_depth``; at most
``max_depth`` vertices.

Cell averages (``view_grid``, ``light_grid`` given; ``precompute btf --directions cell``, the default)
------------------------------------------------------------------------------------------------------
The texture is a table over the view and light grids, and the renderer looks it up (and its lobes) at
every direction in between. A point sample at the grid direction stands for its whole cell only if the
radiance is smooth over the cell, which fibre glints are not: the 1-degree R lobes of the fibres make
r(l, v) change by tens of per cent within a few degrees. Measured on the flat 4/1 satin at the grid's
view (0.22, -0.54, 0.81) and light (0.32, 0.13, 0.94), single scattering: the acquisition's point sample
0.115 (luminance per unit irradiance) equals fiberpath seen from far away (0.1153, a 0.45 degree field of
view), but fiberpath with the sweep's kind of camera, whose view changes by +-6 degrees across the image,
gives 0.0738: the grid direction sits on a glint. So each sample s takes its view uniformly over the
view's grid cell (``cell_direction``: uniform in cos theta and phi over the ring and azimuth range,
i.e. uniform in solid angle), and each path takes one direction per light uniformly over that light's
cell, used at all its vertices: a texel's sample for (view cell, light cell) estimates the mean of
r(l, v) over both cells. Random dimensions: 2-3 the view, 4 + 2k and 5 + 2k light k, then the
vertices'. Without the grids (``--directions grid``) the samples are the paper's point samples and the
dimensions as before (the same bytes as before 2026-12-02).

Half-vector light cells (``light_coords`` HALF, ``precompute btf --light-coords half``): light k is then cell k of
the half-vector grid seen from the sample's view (``stages.core.btf.half_cell_direction``: the view's mirror
direction about a half vector uniform over the cell, with the same random dimensions; without the grids, about
the cell's centre), and a cell whose light would lie below the fabric adds nothing (its shadow ray is not cast).

Light from below (``light_coords`` SPHERE, ``precompute btf --light-domain sphere``): the light grid's cells and then
their mirror images below the fabric (``stages.core.btf.sphere_cell_direction``, the same random dimensions as the
hemisphere's 2 L lights); a light below is lit like one above, its shadow ray leaving through the slab's bottom
(``periodic.light_reaches``), so r(l, v) there is the light the fabric lets through towards v.

The texture's plane (``precompute btf --plane``). A texel holds what the rays through its point of the plane see,
and the renderer puts the texture on that plane. A fibre at depth d below the plane is seen through the texel
(d tan theta) away from it, in the view's azimuth: views a grid cell apart see it through texels that far apart,
and the renderer interpolates four views and each sample averages its view's cell, which blurs every feature by
its distance from the plane times the cells' angular width. The top face puts the whole slab's thickness below
the plane (on the knit tiling 0.12 of a 0.25 x 0.2 stitch: a third of a stitch at 35 degrees); its middle
(``--plane middle``) halves the largest distance; ``--plane surface`` takes the median height of what the views
see (``hit_heights``: the first hits of rays from every grid view), which minimises the mean distance of the seen
fibres from the plane. One plane cannot be near every fibre of an open knit: its yarns' tops and the loops below
them lie a slab's depth apart. ``--plane relief`` gives every texel its own plane, the median height of the first
hits of rays straight down through its footprint (``hit_heights`` on the texel grid; where most of them pass through
the fabric, the slab's bottom: a hole is a pit, and a ray into it meets the yarns around it or below it where their
own texels stand), so the rays of every view through the texel meet the fibres it shows where they cross; the
renderer finds the texel a pixel's ray meets by walking the height field (relief mapping, Policarpo, Oliveira and
Comba 2005; ``stages.render.integrators.btf``).

Per (texel, view): ``radiance`` = the mean over the samples that hit (the texture's colour where it
is opaque: the renderer blends it with what lies behind by alpha, so the hole is not counted twice),
``alpha`` = hits / spp. Per texel: the sum of the first hits' surface normals (the capsule's outward
normal at the hit, whatever the material) over all views and samples, for the average normal.

Random numbers: ``uniform(seed, key, dim)`` with key = (texel * V + view) * spp + sample, so the
result is the same whatever the thread count or the split of texels into chunks.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.btf import HALF, SPHERE, cell_direction, half_cell_direction, sphere_cell_direction
from stages.core.dispatch import runtime_value
from stages.core.geometry.capsule import capsule_normal
from stages.core.geometry.stack import stack_array, stack_vector3
from stages.core.rng import uniform
from stages.core.shading.material import CTX_SIZE, material_eval_pdf
from stages.core.threads import chunk_kernel, for_chunks
from stages.precompute.periodic import (
    DIRECTION_DIMS,
    PathScratch,
    PeriodicPaths,
    light_reaches,
    periodic_hit,
    periodic_path,
    register_tally,
    wrap_into_period,
)

FIRST_DIMS = 2           # the point's jitter (then, for cell averages, the view's and every light's cell jitter)
JOB_CHUNKS_PER_THREAD = 64  # (texel, view) jobs cost from a few rays (nothing hit) to spp full paths: small runs
                            # balance threads


BtfLights = namedtuple("BtfLights", ["radiance", "lights", "below"])
BtfLights.__doc__ = """What one acquisition path records (a tally of ``periodic.periodic_path``): for every light
direction of ``lights`` (L, 3) (unit irradiance), the radiance it sends along the path into ``radiance`` (L, 3).
``below``: lights below the fabric are lights (a sphere table's lower half, whose shadow rays leave through the
bottom); else such a direction is a half-vector cell's "no light"."""


@njit(cache=True)
def _btf_light_vertex(tally, paths, v, mat, nf, tp, seed, key, base):
    """``periodic.light_vertex`` for an acquisition path: next-event estimation towards every light."""
    lights = tally.lights
    radiance = tally.radiance
    wl = v.wl
    tp0, tp1, tp2 = tp
    rays = 0
    for k in range(lights.shape[0]):
        if lights[k, 2] <= 0.0 and not tally.below:   # a half-vector cell's light below the fabric: none
            continue
        wl[0] = lights[k, 0]
        wl[1] = lights[k, 1]
        wl[2] = lights[k, 2]
        f0, f1, f2, _pf = material_eval_pdf(mat, v.ctx, v.t_tan, v.n, v.wi, wl)
        if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
            continue
        rays += 1
        if light_reaches(paths, v, nf):
            radiance[k, 0] += tp0 * f0
            radiance[k, 1] += tp1 * f1
            radiance[k, 2] += tp2 * f2
    return rays


register_tally(BtfLights, _btf_light_vertex)   # the lights are counted at the vertices: an escape adds nothing


@njit(cache=True)
def _first_normal(sc, h, out):
    """Add the outward capsule normal at the first hit ``h`` (in its wrapped piece's coordinates)."""
    a = sc.seg_a[h.wrapped]
    P = sc.points
    nx, ny, nz, _s = capsule_normal(h.fx, h.fy, h.fz, P[a, 0], P[a, 1], P[a, 2],
                                    P[a + 1, 0], P[a + 1, 1], P[a + 1, 2])
    out[0] += nx
    out[1] += ny
    out[2] += nz


@njit(cache=True, _nrt=False)
def texel_view_samples(paths, res, texel, vx, vy, vz, light_dirs, spp, seed, key0, radiance, normal, view_cell,
                       view_grid, light_grid, light_coords, lights_now, z_plane):
    """Radiance sums (L, 3) of texel ``texel`` seen from v over ``spp`` samples into ``radiance`` (zeroed
    here) and the first-hit normals into ``normal`` (added); returns (hits, rays). With view_grid[0] > 0
    each sample's view is uniform in grid cell ``view_cell`` and each light's direction uniform in its
    cell of light_grid (module doc, "Cell averages"; ``lights_now`` (L, 3) scratch), else v and
    ``light_dirs`` themselves. ``light_coords`` HALF: light k is half-vector cell k of light_grid seen from the
    sample's view (``stages.core.btf.half_cell_direction``: uniform over the cell with the grids, its centre
    without), ``light_dirs`` then only gives the count; SPHERE: lights L/2 .. L - 1 the mirror images below the
    fabric of lights 0 .. L/2 - 1 (``light_grid`` the hemisphere's). Compiled without reference counting (its
    vectors on the machine stack): the two workers of ``acquire_texels`` would otherwise count references on the
    same arrays for every ray. The samples' points lie on the plane at height ``z_plane`` (module doc, "The
    texture's plane").
    18 parameters: one (texel, view) job (texel, view and its cell, spp, key), the light set, the grids and their
    light coordinates, four output or scratch arrays and the texture's plane; the fabric is one record
    (``PeriodicPaths``)."""
    W = paths.W
    H = paths.H
    L = light_dirs.shape[0]
    for k in range(L):
        for c in range(3):
            radiance[k, c] = 0.0
        for c in range(3):
            lights_now[k, c] = light_dirs[k, c]
    jitter = view_grid[0] > 0
    half = light_coords == HALF
    sphere = light_coords == SPHERE
    first_dims = FIRST_DIMS + (2 + 2 * L if jitter else 0)
    if half and not jitter:   # the cells' centres seen from v, the same for every sample
        for k in range(L):
            lx, ly, lz = half_cell_direction(k, light_grid[0], light_grid[1], 0.5, 0.5, vx, vy, vz)
            lights_now[k, 0] = lx
            lights_now[k, 1] = ly
            lights_now[k, 2] = lz
    iy = texel // res
    ix = texel - iy * res
    v = PathScratch(stack_vector3(), stack_vector3(), stack_vector3(), stack_vector3(), stack_vector3(),
                    stack_vector3(), stack_array(CTX_SIZE, np.float64))
    tally = BtfLights(radiance, lights_now, sphere)
    hits = 0
    rays = 0
    for s in range(spp):
        key = key0 + s
        px = (ix + uniform(seed, key, 0)) * W / res
        py = (iy + uniform(seed, key, 1)) * H / res
        if jitter:   # this sample's view and light directions, uniform over their grid cells
            vx, vy, vz = cell_direction(view_cell, view_grid[0], view_grid[1], uniform(seed, key, FIRST_DIMS),
                                        uniform(seed, key, FIRST_DIMS + 1))
            for k in range(L):
                u0 = uniform(seed, key, FIRST_DIMS + 2 + 2 * k)
                u1 = uniform(seed, key, FIRST_DIMS + 3 + 2 * k)
                if half:
                    lx, ly, lz = half_cell_direction(k, light_grid[0], light_grid[1], u0, u1, vx, vy, vz)
                elif sphere:
                    lx, ly, lz = sphere_cell_direction(k, light_grid[0], light_grid[1], u0, u1)
                else:
                    lx, ly, lz = cell_direction(k, light_grid[0], light_grid[1], u0, u1)
                lights_now[k, 0] = lx
                lights_now[k, 1] = ly
                lights_now[k, 2] = lz
        rays += 1
        ox, oy = px, py
        if z_plane != paths.z_hi:   # back along v from the plane to the slab's top, kept within one period
            up = (paths.z_hi - z_plane) / vz
            ox, oy = wrap_into_period(px + up * vx, py + up * vy, W, H)
        h = periodic_hit(paths.scene, paths.z_lo, paths.z_hi, ox, oy, paths.z_hi, -vx, -vy, -vz, runtime_value(-1),
                         paths.max_dist)
        if math.isinf(h.t):
            continue
        hits += 1
        _first_normal(paths.scene, h, normal)
        v.wi[0] = vx
        v.wi[1] = vy
        v.wi[2] = vz
        rays += periodic_path(paths, tally, v, h, seed, key, first_dims, DIRECTION_DIMS)
    return hits, rays


@njit(cache=True)
def hit_heights(paths, view_dirs, rays_per_view, seed, cells=1):
    """(V, cells^2, rays_per_view) the heights z of the first fibre hits of ``rays_per_view`` rays per view of
    ``view_dirs`` (V, 3) and cell of a cells x cells grid over the period into the periodic fabric, each entering the
    slab's top at a uniform point of its cell (counter-based numbers: key = (view x cells^2 + cell) x rays_per_view +
    ray, dimensions 0-1; cell row-major as the texels); NaN where a ray passes through. ``precompute btf --plane
    surface``: one cell, the median of every view's hits is the plane; ``--plane relief``: the texel grid seen
    straight down, each texel's median its own plane (module doc, "The texture's plane")."""
    V = view_dirs.shape[0]
    C = cells * cells
    out = np.full((V, C, rays_per_view), np.nan)
    for v in range(V):
        for cell in range(C):
            iy = cell // cells
            ix = cell - iy * cells
            for s in range(rays_per_view):
                key = (v * C + cell) * rays_per_view + s
                h = periodic_hit(paths.scene, paths.z_lo, paths.z_hi, (ix + uniform(seed, key, 0)) * paths.W / cells,
                                 (iy + uniform(seed, key, 1)) * paths.H / cells, paths.z_hi, -view_dirs[v, 0],
                                 -view_dirs[v, 1], -view_dirs[v, 2], runtime_value(-1), paths.max_dist)
                if not math.isinf(h.t):
                    out[v, cell, s] = h.z
    return out


def acquire_texels(sc, z_lo, z_hi, W, H, mat_of_fiber, mats, res, t0, t1, view_dirs, light_dirs, spp, seed,
                   max_depth, rr_depth, max_dist, eps, view_grid, light_grid, light_coords, z_plane=None):
    """Texels t0..t1-1 (row-major ids of the res x res grid): (radiance (T, V, L, 3) float32 mean over the
    hits, alpha (T, V) float32, normal sums (T, 3), rays cast (T,)) -- module doc. ``view_grid`` and
    ``light_grid`` (n_theta, n_phi) of the grids that ``view_dirs`` and ``light_dirs`` are: cell averages
    (module doc); (0, 0): the directions themselves. ``light_coords``: ``stages.core.btf.HEMISPHERE``, HALF
    (``light_grid`` then the half-vector grid's (nx, ny), given also without cell averages) or SPHERE
    (``light_dirs`` the hemisphere grid of ``light_grid`` and its mirror image below). All three are always
    passed (no defaults), so every caller shares one compiled specialisation of the kernel. ``z_plane``: the
    texture's plane (module doc; None: the top face z_hi, the paper's; a number: one plane; an array (res^2,): each
    texel's own plane, ``--plane relief``). (texel, view) jobs on threads (``stages.core.threads``)."""
    T = t1 - t0
    V = view_dirs.shape[0]
    L = light_dirs.shape[0]
    radiance = np.zeros((T, V, L, 3), np.float32)
    alpha = np.zeros((T, V), np.float32)
    normal = np.zeros((T, V, 3))
    rays = np.zeros((T, V), np.int64)
    paths = PeriodicPaths(sc, z_lo, z_hi, W, H, mat_of_fiber, mats, max_depth, rr_depth, max_dist, eps)
    planes = np.empty(res * res)
    planes[:] = z_hi if z_plane is None else z_plane
    for_chunks(_texel_view_jobs, T * V, paths, res, t0, view_dirs, light_dirs, spp, seed, view_grid, light_grid,
               light_coords, planes, radiance, alpha, normal, rays,
               chunks_per_thread=JOB_CHUNKS_PER_THREAD)
    return (radiance, alpha) + _view_sums(normal, rays)


@njit(cache=True)
def _view_sums(normal, rays):
    return normal.sum(axis=1), rays.sum(axis=1)


@chunk_kernel
def _texel_view_jobs(paths, res, t0, view_dirs, light_dirs, spp, seed, view_grid, light_grid, light_coords, planes,
                     radiance, alpha, normal, rays, j0, j1):
    """``acquire_texels``' jobs j0 .. j1 - 1 (job = texel row i, view v: i V + v); ``planes`` (res^2,) each texel's
    plane.
    17 parameters: a ``for_chunks`` chunk kernel: the jobs' inputs, the four output arrays and the chunk's range."""
    V = view_dirs.shape[0]
    L = light_dirs.shape[0]
    acc = np.empty((L, 3))   # per chunk (as numba's parallel loop hoisted them); texel_view_samples fills them
    now = np.empty((L, 3))
    for job in range(j0, j1):
        i = job // V
        v = job - i * V
        texel = t0 + i
        key0 = (texel * V + v) * spp
        hits, r = texel_view_samples(paths, res, texel, view_dirs[v, 0], view_dirs[v, 1], view_dirs[v, 2],
                                     light_dirs, spp, seed, key0, acc, normal[i, v], v, view_grid, light_grid,
                                     light_coords, now, planes[texel])
        rays[i, v] = r
        alpha[i, v] = hits / spp
        if hits > 0:
            for k in range(L):
                for c in range(3):
                    radiance[i, v, k, c] = acc[k, c] / hits


def texel_frames(normal_sums):
    """Average normal and tangent per texel (§4): n = the normalised sum of first-hit normals (+z where
    nothing was hit), b = the unit vector perpendicular to n and the x axis, t = b x n. (T, 2, 3)."""
    n = np.asarray(normal_sums, np.float64).reshape(-1, 3).copy()
    norm = np.linalg.norm(n, axis=1)
    n[norm <= 1e-12] = (0.0, 0.0, 1.0)
    n /= np.linalg.norm(n, axis=1)[:, None]
    b = np.cross(n, np.array([1.0, 0.0, 0.0]))
    bad = np.linalg.norm(b, axis=1) < 1e-6          # n along x: take y as the binormal
    b[bad] = np.cross(np.cross(n[bad], np.array([0.0, 1.0, 0.0])), n[bad])
    b /= np.linalg.norm(b, axis=1)[:, None]
    t = np.cross(b, n)
    t /= np.linalg.norm(t, axis=1)[:, None]
    return np.stack([n, t], axis=1)
