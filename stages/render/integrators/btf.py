"""A fitted cloth texture on a triangle mesh (``--method btf``, seed 002 §6 and §6.1, in software).

Every camera ray finds its nearest triangle (``stages.core.geometry.triangles``) and there, the paper's
four steps (§6):

1. **normal**: the vertex normals interpolated with the hit's barycentrics, normalised; the tangent t
   is the triangle's dP/dx (x the pattern's first coordinate) made orthogonal to that normal;
   b = n x t. (x = t, y = b, z = n) is the surface's local frame, which the texture calls pattern
   space. A ray that meets a triangle's back face sees the cloth's other side: n is flipped towards
   the viewer (t kept, so b flips too), and the back shows the same texture, mirrored.
2. **texel**: the pattern coordinate (the corners' pattern coordinates interpolated, counted in
   repeats) picks the exemplar whose texture is read -- on a tiling of several exemplars (a damask),
   the one the tiling's block map places at that flat point (``texel_exemplar``, the tile stage's own
   ``stages.core.blocks.block_of``; none: no cloth there, the ray goes on); on a mesh, the first --
   and, counted in that exemplar's repeats, modulo 1 picks texel (floor(frac(y) r), floor(frac(x) r))
   of a level of r x r texels: the nearest texel, no filtering within a level.
3. **f_r**: light l and view v = -d in the local frame give f_r(l, v) = T(v) . f_1(l, v) (Eq. 1-2: the
   Lafortune lobes with l, v in the texel's own frame, ``stages.core.btf``; T(v) and alpha bilinear on
   the view grid with ``grid_weights``, once per ray for every texel it reads). f_r includes l_z.
4. **radiance**: a directional light of irradiance E (``stages.render.lights``) adds E f_r(l, v);
   an SG light of power P adds (P / n) sum_i f_r(l_i, v) over n = 64 fixed stratified points l_i of its
   own distribution (``sg_f1``: exact in the sharp limit, where the light grid would miss the lobe);
   environment maps are summed over the texture's own light grid (the equal-area hemisphere grid of
   the fit, every direction 2 pi / L of solid angle): sum_j (2 pi / L) L_light(l_j) f_r(l_j, v), l_j
   taken from the local frame to the world; a constant light (radiance L from everywhere) by the same
   sum, which then does not depend on the frame: L sum_j (2 pi / L) f_1(l_j, v) is tabulated per texel
   at the view grid's directions once per render (``sky_table``) and read at the view's grid weights as
   T(v) is (``sky_f1``; exact at the grid's views, interpolated between them).

**The tabulated model** (``tabulated``; ``stages.precompute.btf_compress``, decoded to ``radiance`` (N, V, L, 3)
float32 once per render): step 3 reads the acquired table instead of the lobes, f_r(l, v) = r(l, v) bilinear on
the view grid and on the light grid (``stages.core.btf.table_rgb``), T(v) = 1 and alpha as before. Everything
else -- mip levels, alpha, lights, shadows, the sky table (``tabulated_sky_table``: the table's own light-grid
sum) -- is the same. A table acquired with light from below too (``precompute btf --light-domain sphere``:
``lower``) lights the surface from its far side as well: a directional or SG light, or an environment map's
direction, behind the surface reads the table's lower half (the light through the cloth), the shadow ray of a
light behind leaving from the far side, and the sky table sums both halves; the Lafortune lobes stay a reflectance
(light from above only).

**Relief** (``relief``; ``precompute btf --plane relief``). A texture acquired with a plane per texel (the height of
what the texel shows from above, ``heights``) is read where the pixel's ray meets that height field, not where it
crosses the surface: ``relief_point`` walks the ray texel by texel through the field (relief mapping, Policarpo et al.
2005) and steps 2-3 read the texel there -- every view of a texel then shows the same fibres, where a single plane
shifts what lies above or below it between the views the lookup interpolates. Front faces only (the field is the
top's); shadow rays read alpha on the surface itself.

**Alpha** (§3, §6): the table's alpha at the view is the texel's coverage for that view, 0 at a hole
in the weave. The ray goes on through the surface (the next hit along the same ray, up to
``max_layers`` surfaces; further ones are not seen) and the pixel is alpha C_front + (1 - alpha)
C_behind, behind being other parts of the mesh, the ground plane (``stages.render.ground``: Lambertian,
lit by the same lights, the same quadrature) or the lights seen directly (the background). ``hit``
(the film's alpha channel) is 1 when the ray met the mesh or the ground, as for every integrator.

**Mip-mapping** (§6.1, ``mip``): one pixel subtends the solid angle (2 tan(fov/2) / width)^2 cos^3 at
angle off the camera axis; at distance t and incidence cos_i to the triangle its footprint on the
surface is t sqrt(solid angle) / cos_i wide along its long axis (what OpenGL's level selection takes).
A level-0 texel on triangle k is sqrt(|dP/dx x dP/dy|) / res wide (dP/dx, dP/dy: the world size of
one repeat along the pattern's axes; for exemplar e that width over sqrt of its ``exemplar_scale``). The
level is log2(footprint / texel) clamped to [0, levels - 1], blended linearly between the two nearest
levels: alpha and alpha-weighted colour (premultiplied), so holes fade into the coarser levels' partial
coverage.

**Shadows** (``shadows``): a directional light's shadow ray from the hit towards the light passes the
mesh's surfaces with their coverage, transmittance prod (1 - alpha), alpha read at each surface for
the ray's direction at the receiver's mip level (up to ``max_layers`` surfaces); the ground blocks it.
The lights of the quadrature are not shadowed.

``BtfIntegrator`` fields: ``mesh`` (``TriangleMesh``); ``shading`` (T, SHADING_SIZE) per triangle: its
corners' unit normals (9), their pattern coordinates in repeats (6), the unit tangent dP/dx (3), the
unit geometric normal (3) and the world width of a level-0 texel on it (1), both for the first exemplar's
repeat; the texture, every exemplar's levels flattened (exemplar e's level l's texel (iy, ix) is row
``levels[e, l, 0] + iy levels[e, l, 1] + ix``, ``levels[e, l, 1]`` its resolution; ``exemplar_scale`` (E, 2) the
first exemplar's period over exemplar e's, which turns a pattern coordinate into e's repeats); ``block_map``
(nbu, nbv) the texture's exemplar per block of the flat fabric (-1: none), ``block_size`` (2) and
``flat_period`` (2) the flat size of a block and of one pattern unit (a mesh: a 1 x 1 map of exemplar 0);
``texels`` (N, TEXEL_HEAD + 12 K) rho (3), the texel frame's n, t, b = n x t (9),
then per lobe and channel C_x, C_y, C_z, N; ``table`` (N, V, 4) float32 T(v) rgb and alpha;
``n_theta``, ``n_phi`` the view grid, ``light_dirs`` (L, 3) the light grid (pattern space), ``l_theta``, ``l_phi``
its shape; ``tabulated`` (bool) and ``radiance`` (N, V, L, 3) float32 the tabulated model's decoded table ((1, 1, 1, 3)
unused for the Lafortune model); ``lower``: the table answers light from below the surface (a sphere table,
``stages.core.btf`` "Light from below": directional, SG and environment light behind the cloth comes through it);
``half`` (0 or 1): the table's lights are half-vector cells (``l_theta`` x
``l_phi`` = nx x ny, read by ``stages.core.btf.half_rgb``; ``light_dirs`` then the fit's hemisphere grid, the
quadrature's) with ``half_valid`` (V, L) their valid fractions ((1, 1) unused otherwise);
``heights`` (N,) each texel row's relief height over the surface (scene units; only level 0's are read),
``relief`` (bool) whether to march them, ``relief_span`` (2) the field's highest and lowest height and ``inv_period``
(2) one over the first exemplar's period (a relief's scene units into pattern units; (1,), False, zeros otherwise);
``lights`` (``LightTable``), ``quad_lights`` how many lights are not directional (the ground's
quadrature), ``env_lights`` how many are environment maps (the surface's quadrature), ``sky`` (N, V, 3)
the ``sky_table`` when ``has_sky`` (a constant light is there; else (1, 1, 3) unused) and ``sky_radiance``
(3) the constant lights' total radiance, ``ground``,
``has_ground``; ``pixel_angle`` 2 tan(fov / 2) / width and ``forward`` the camera axis; ``mip``,
``shadows`` (0 or 1), ``max_layers``, ``eps`` (ray offset, scene units). Nothing is random: the
estimate is exact per camera ray (the tile loop's jitter places the ray in its pixel).

Speed: the estimator is inlined into the tile loop and reads the integrator through ``borrowed``, a
copy whose arrays carry no reference count: numba's atomic reference counting of the integrator's
arrays at every helper call, and passing the whole integrator to a function once per ray, cost more
than tracing and shading together (measured: 0.14 -> 0.09 s a 730 x 400 frame on one core). The rare
paths (shadow rays, the light-grid quadrature, the ground) and the per-light texel models
(``texel_f1_rgb``, ``table_rgb``) stay separate functions, which keeps the tile loop's first compilation
near 50 s. The triangle traversal keeps its stack on the machine stack
(``stages.core.geometry.triangles``), so a ray allocates nothing.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from stages.core.blocks import block_of
from stages.core.btf import LOBE_PARAMS, grid_weights, half_rgb, lafortune_lobe, table_rgb
from stages.core.dispatch import is_tuple_class
from stages.core.geometry.triangles import TriangleHit, mesh_intersect
from stages.render.ground import ground_intersect
from stages.render.integrator import PathSample, radiance
from stages.render.lights import CONSTANT, DIRECTIONAL, SG, environment_radiance, light_eval, light_sample

SG_U = 8    # SG lights: stratified points along the lobe's cos theta ...
SG_V = 8    # ... and around its axis (sg_f1)

BtfIntegrator = namedtuple("BtfIntegrator", [
    "mesh", "shading", "texels", "table", "levels", "exemplar_scale", "block_map", "block_size", "flat_period",
    "n_theta", "n_phi", "light_dirs", "lights", "quad_lights", "env_lights", "sky", "sky_radiance", "has_sky",
    "ground", "has_ground", "pixel_angle", "forward", "mip", "shadows", "max_layers", "eps", "tabulated", "radiance",
    "l_theta", "l_phi", "half", "half_valid", "lower", "heights", "relief", "relief_span", "inv_period"])

MAX_LAYERS = 4
RELIEF_MAX_CELLS = 1024  # relief mapping: at most this many texels walked along one ray (grazing views)
RELIEF_INSIDE = 1e-6     # relief mapping: a wall's hit moved this fraction of its texel's stretch into the texel
RELIEF_MIN_COS = 0.05    # relief mapping: views nearer the surface march as if at this cos theta (a finite offset)
INV_PI = 1.0 / math.pi
# ``shading`` columns per triangle
S_NORMALS = 0        # corner normals n0, n1, n2 (9)
S_PATTERN = 9        # corner pattern coordinates (x0, y0, x1, y1, x2, y2)
S_TANGENT = 15       # unit dP/dx
S_GEOMETRIC = 18     # unit geometric normal (e1 x e2)
S_TEXEL_WIDTH = 21   # world width of a level-0 texel
SHADING_SIZE = 22
# ``texels`` columns
T_RHO = 0
T_FRAME = 3          # n (3), t (3), b = n x t (3)
TEXEL_HEAD = 12      # then lobe k, channel c at TEXEL_HEAD + (3 k + c) LOBE_PARAMS: C_x, C_y, C_z, N

# the local frame at a hit: normal, tangent, binormal, pattern coordinate, |cos| of incidence, hit point
SurfaceFrame = namedtuple("SurfaceFrame", ["nx", "ny", "nz", "tx", "ty", "tz", "bx", "by", "bz", "pu", "pv",
                                           "cos_i", "px", "py", "pz"])


# ------------------------------------------------------------------------------------------------
def _without_meminfo(context, builder, ty, val):
    if isinstance(ty, types.Array):
        ary = context.make_array(ty)(context, builder, value=val)
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        ary.parent = cgutils.get_null_value(ary.parent.type)
        return ary._getvalue()
    if isinstance(ty, types.BaseTuple):
        for i, t in enumerate(ty.types):
            val = builder.insert_value(val, _without_meminfo(context, builder, t, builder.extract_value(val, i)), i)
    return val


@intrinsic
def borrowed(typingctx, value):
    """``value`` (an array or a nested tuple of arrays) with every array's reference count detached: the
    same data, no atomic increments and decrements wherever it is passed. Valid while the caller
    holds ``value`` (here: the tile loop holds the integrator for the whole tile)."""
    def codegen(context, builder, sig, args):
        return _without_meminfo(context, builder, sig.args[0], args[0])
    return value(value), codegen


# ------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def surface_frame(shading, tri, b1, b2, t, ox, oy, oz, dx, dy, dz, eps):
    """The local frame at the hit (t, tri, b1, b2) of ray o + t d, facing the ray's origin (module doc);
    the hit point is moved ``eps`` off the surface towards that side."""
    S = shading
    w0 = 1.0 - b1 - b2
    gx = S[tri, S_GEOMETRIC]
    gy = S[tri, S_GEOMETRIC + 1]
    gz = S[tri, S_GEOMETRIC + 2]
    gd = gx * dx + gy * dy + gz * dz
    side = -1.0 if gd > 0.0 else 1.0            # which side of the triangle the ray comes from
    nx = w0 * S[tri, 0] + b1 * S[tri, 3] + b2 * S[tri, 6]
    ny = w0 * S[tri, 1] + b1 * S[tri, 4] + b2 * S[tri, 7]
    nz = w0 * S[tri, 2] + b1 * S[tri, 5] + b2 * S[tri, 8]
    nl = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nl > 0.0:
        nx = side * nx / nl
        ny = side * ny / nl
        nz = side * nz / nl
    else:
        nx = side * gx
        ny = side * gy
        nz = side * gz
    tx = S[tri, S_TANGENT]
    ty = S[tri, S_TANGENT + 1]
    tz = S[tri, S_TANGENT + 2]
    c = tx * nx + ty * ny + tz * nz               # the tangent made orthogonal to n
    tx -= c * nx
    ty -= c * ny
    tz -= c * nz
    tl = math.sqrt(tx * tx + ty * ty + tz * tz)
    if tl < 1e-9:   # dP/dx along the normal: any tangent (the texel's own frame still holds its shape)
        if abs(nx) < 0.9:
            tx, ty, tz = 1.0 - nx * nx, -nx * ny, -nx * nz
        else:
            tx, ty, tz = -ny * nx, 1.0 - ny * ny, -ny * nz
        tl = math.sqrt(tx * tx + ty * ty + tz * tz)
    tx /= tl
    ty /= tl
    tz /= tl
    p = S_PATTERN
    pu = S[tri, p] + b1 * (S[tri, p + 2] - S[tri, p]) + b2 * (S[tri, p + 4] - S[tri, p])
    pv = S[tri, p + 1] + b1 * (S[tri, p + 3] - S[tri, p + 1]) + b2 * (S[tri, p + 5] - S[tri, p + 1])
    e = eps * side
    return SurfaceFrame(nx, ny, nz, tx, ty, tz, ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx, pu, pv,
                        abs(gd), ox + t * dx + e * gx, oy + t * dy + e * gy, oz + t * dz + e * gz)


@njit(cache=True, inline="always")
def to_local(f, wx, wy, wz):
    """World direction into the local frame (pattern space)."""
    return (wx * f.tx + wy * f.ty + wz * f.tz, wx * f.bx + wy * f.by + wz * f.bz, wx * f.nx + wy * f.ny + wz * f.nz)


@njit(cache=True, inline="always")
def texel_exemplar(it, pu, pv):
    """(exemplar e, its pattern coordinate) at pattern coordinate (pu, pv): the block map's exemplar of the flat
    point (pu, pv) x ``flat_period`` (``stages.core.blocks.block_of``), -1 where the map places none; the
    coordinate counted in repeats of exemplar e (``exemplar_scale``)."""
    bm = it.block_map
    i, j, _ri, _rj = block_of(pu * it.flat_period[0], pv * it.flat_period[1], it.block_size, bm.shape[0],
                              bm.shape[1])
    e = bm[i, j]
    if e < 0:
        return -1, pu, pv
    return e, pu * it.exemplar_scale[e, 0], pv * it.exemplar_scale[e, 1]


@njit(cache=True, inline="always")
def texel_index(levels, e, level, pu, pv):
    """Row of the flattened texture: exemplar e's level ``level``'s nearest texel to pattern coordinate (pu, pv)."""
    r = levels[e, level, 1]
    ix = min(int((pu - math.floor(pu)) * r), r - 1)
    iy = min(int((pv - math.floor(pv)) * r), r - 1)
    return levels[e, level, 0] + iy * r + ix


@njit(cache=True, inline="always")
def relief_height(it, pu, pv):
    """The height field's height (over the surface, scene units) at pattern coordinate (pu, pv): the level-0 texel's
    (``heights``); the span's bottom where the block map places no cloth."""
    e, qu, qv = texel_exemplar(it, pu, pv)
    if e < 0:
        return it.relief_span[1]
    return it.heights[texel_index(it.levels, e, 0, qu, qv)]


@njit(cache=True)
def relief_point(it, pu, pv, vx, vy, vz):
    """Relief mapping (Policarpo, Oliveira and Comba 2005, "Real-time relief mapping on arbitrary polygonal
    surfaces", §3), exact for a field that is constant over each texel: the pattern coordinate where the ray towards
    -v (local frame) through the surface's point (pu, pv) first meets the texture's height field (``precompute btf
    --plane relief``: each texel acquired through its own plane). The ray's point at height d over the surface lies
    at (pu, pv) + d (v_x, v_y) / v_z in scene units, over the first exemplar's period in pattern units
    (``inv_period``). From the span's top (``relief_span``) down, the ray is walked texel by texel over the first
    exemplar's level-0 grid (Amanatides and Woo 1987): over texel c it descends from d_in to d_out; it meets c's wall
    if h_c >= d_in, c's top (at d = h_c) if h_c >= d_out; else it goes on to the next texel. The heights scale with
    the texture: on a mesh of another size the relief scales with its repeat."""
    sz = max(vz, RELIEF_MIN_COS)
    res = it.levels[0, 0, 1]
    su = vx / sz * it.inv_period[0]
    sv = vy / sz * it.inv_period[1]
    top = it.relief_span[0]
    span = top - it.relief_span[1]
    # texel coordinates along the walk: x(t) = x0 + t gx, t = top - d from 0 to span
    x0 = (pu + top * su) * res
    y0 = (pv + top * sv) * res
    gx = -su * res
    gy = -sv * res
    cx = math.floor(x0)
    cy = math.floor(y0)
    step_x = 1.0 if gx > 0.0 else -1.0
    step_y = 1.0 if gy > 0.0 else -1.0
    dt_x = 1.0 / abs(gx) if gx != 0.0 else math.inf      # t between two x boundaries
    dt_y = 1.0 / abs(gy) if gy != 0.0 else math.inf
    next_x = ((cx + 1.0 - x0) if gx > 0.0 else (x0 - cx)) * dt_x if gx != 0.0 else math.inf
    next_y = ((cy + 1.0 - y0) if gy > 0.0 else (y0 - cy)) * dt_y if gy != 0.0 else math.inf
    t_in = 0.0
    t = span
    for _ in range(RELIEF_MAX_CELLS):
        t_out = min(next_x, next_y, span)
        h = relief_height(it, (cx + 0.5) / res, (cy + 0.5) / res)
        if h >= top - t_in:             # the texel's wall (or, at the start, its top at the span's top)
            t = t_in + RELIEF_INSIDE * (t_out - t_in)
            break
        if h >= top - t_out:            # the texel's top
            t = top - h
            break
        if t_out >= span:
            break
        t_in = t_out
        if next_x < next_y:
            cx += step_x
            next_x += dt_x
        else:
            cy += step_y
            next_y += dt_y
    d = top - t
    return pu + d * su, pv + d * sv


@njit(cache=True, inline="always")
def mip_blend(it, width, texel_width):
    """(level l0, level l1, weight of l1) for a footprint ``width`` over level-0 texels of ``texel_width``."""
    top = it.levels.shape[1] - 1
    if not it.mip or top == 0 or not (width > 0.0 and texel_width > 0.0):
        return 0, 0, 0.0
    lam = math.log2(width / texel_width)
    if not lam > 0.0:
        return 0, 0, 0.0
    if lam >= top:
        return top, top, 0.0
    l0 = int(math.floor(lam))
    return l0, l0 + 1, lam - l0


@njit(cache=True, inline="always")
def footprint(it, t, cos_i, dx, dy, dz):
    """Width of the pixel's footprint on the surface along its long axis (module doc)."""
    c = max(dx * it.forward[0] + dy * it.forward[1] + dz * it.forward[2], 1e-3)   # cos off the camera axis
    return t * it.pixel_angle * c * math.sqrt(c) / max(cos_i, 1e-6)


@njit(cache=True, inline="always")
def view_lookup(table, idx, i0, i1, i2, i3, w0, w1, w2, w3, c):
    """T(v) channel c (alpha: c = 3) of texel row idx with the view's grid weights."""
    return w0 * table[idx, i0, c] + w1 * table[idx, i1, c] + w2 * table[idx, i2, c] + w3 * table[idx, i3, c]


@njit(cache=True)
def texel_f1_rgb(texels, n_lobes, idx, lx, ly, lz, vx, vy, vz):
    """f_1(l, v) of texel row idx, three channels (Eq. 2; ``stages.core.btf.texel_f1`` on the packed
    texel, with l and v taken into the texel frame once for the three channels); 0 for l_z <= 0. A plain call,
    not inlined (as ``stages.core.btf.table_rgb``): inlined at its two call sites per ``add_f1`` it added 15 s to
    the tile loop's first compilation (65-71 -> 53 s) and no measurable speed (``bench/bench_btf.py``)."""
    if lz <= 0.0:
        return 0.0, 0.0, 0.0
    X = texels
    f = T_FRAME
    ax = lx * X[idx, f + 3] + ly * X[idx, f + 4] + lz * X[idx, f + 5]     # l' = (l.t, l.b, l.n)
    ay = lx * X[idx, f + 6] + ly * X[idx, f + 7] + lz * X[idx, f + 8]
    az = lx * X[idx, f] + ly * X[idx, f + 1] + lz * X[idx, f + 2]
    cx = vx * X[idx, f + 3] + vy * X[idx, f + 4] + vz * X[idx, f + 5]     # v'
    cy = vx * X[idx, f + 6] + vy * X[idx, f + 7] + vz * X[idx, f + 8]
    cz = vx * X[idx, f] + vy * X[idx, f + 1] + vz * X[idx, f + 2]
    s0 = X[idx, T_RHO]
    s1 = X[idx, T_RHO + 1]
    s2 = X[idx, T_RHO + 2]
    for k in range(n_lobes):
        q = TEXEL_HEAD + 3 * k * LOBE_PARAMS
        s0 += lafortune_lobe(X[idx, q], X[idx, q + 1], X[idx, q + 2], X[idx, q + 3], ax, ay, az, cx, cy, cz)
        q += LOBE_PARAMS
        s1 += lafortune_lobe(X[idx, q], X[idx, q + 1], X[idx, q + 2], X[idx, q + 3], ax, ay, az, cx, cy, cz)
        q += LOBE_PARAMS
        s2 += lafortune_lobe(X[idx, q], X[idx, q + 1], X[idx, q + 2], X[idx, q + 3], ax, ay, az, cx, cy, cz)
    return lz * s0, lz * s1, lz * s2     # Eq. 2: l_z (rho + sum of lobes)


@njit(cache=True, inline="always")
def texel_rgb(it, idx, lx, ly, lz, vx, vy, vz):
    """f_1(l, v) of texel row idx, three channels, by the texture's model: the tabulated table (``tabulated``:
    ``stages.core.btf.table_rgb``, its T(v) is 1) or the Lafortune lobes (``texel_f1_rgb``)."""
    if it.tabulated:
        if it.half:
            return half_rgb(it.radiance, it.half_valid, idx, it.l_theta, it.l_phi, lx, ly, lz, it.n_theta, it.n_phi,
                            vx, vy, vz)
        return table_rgb(it.radiance, idx, it.l_theta, it.l_phi, lx, ly, lz, it.n_theta, it.n_phi, vx, vy, vz)
    texels = it.texels
    return texel_f1_rgb(texels, (texels.shape[1] - TEXEL_HEAD) // (3 * LOBE_PARAMS), idx, lx, ly, lz, vx, vy, vz)


@njit(cache=True, inline="always")
def add_f1(s, it, ia, ib, two, lx, ly, lz, vx, vy, vz, e0, e1, e2):
    """The sums s = (a r, a g, a b, b r, b g, b b) plus (e0, e1, e2) f_1(l, v) of texel row ia and, when ``two``,
    of row ib (``texel_rgb``).
    14 parameters: the sums, the integrator, the two rows, l and v as scalars, the weights."""
    f0, f1, f2 = texel_rgb(it, ia, lx, ly, lz, vx, vy, vz)
    sa0 = s[0] + e0 * f0
    sa1 = s[1] + e1 * f1
    sa2 = s[2] + e2 * f2
    if not two:
        return sa0, sa1, sa2, s[3], s[4], s[5]
    f0, f1, f2 = texel_rgb(it, ib, lx, ly, lz, vx, vy, vz)
    return sa0, sa1, sa2, s[3] + e0 * f0, s[4] + e1 * f1, s[5] + e2 * f2


@njit(cache=True, inline="always")
def add6(s, q):
    """The element-wise sum of two 6-tuples of sums (a r, a g, a b, b r, b g, b b)."""
    return s[0] + q[0], s[1] + q[1], s[2] + q[2], s[3] + q[3], s[4] + q[4], s[5] + q[5]


@njit(cache=True)
def layer_alpha(it, tri, b1, b2, t, ox, oy, oz, dx, dy, dz, l0, l1, fl):
    """Coverage of the surface a shadow ray (direction d) hits, for the line along d, at mip (l0, l1, fl).
    14 parameters: the integrator, the triangle hit (triangle, barycentrics, t), the ray and the mip level (two
    levels and their blend)."""
    f = surface_frame(it.shading, tri, b1, b2, t, ox, oy, oz, dx, dy, dz, 0.0)
    e, pu, pv = texel_exemplar(it, f.pu, f.pv)
    if e < 0:
        return 0.0
    vx, vy, vz = to_local(f, -dx, -dy, -dz)
    i0, i1, i2, i3, w0, w1, w2, w3 = grid_weights(it.n_theta, it.n_phi, vx, vy, vz)
    a = view_lookup(it.table, texel_index(it.levels, e, l0, pu, pv), i0, i1, i2, i3, w0, w1, w2, w3, 3)
    if fl > 0.0:
        a1 = view_lookup(it.table, texel_index(it.levels, e, l1, pu, pv), i0, i1, i2, i3, w0, w1, w2, w3, 3)
        a = (1.0 - fl) * a + fl * a1
    return min(max(a, 0.0), 1.0)


@njit(cache=True)
def shadow_transmittance(it, px, py, pz, lx, ly, lz, l0, l1, fl):
    """(fraction of a directional light's beam (towards l) reaching p, rays traced): the ground blocks it,
    each mesh surface passes 1 - its coverage (module doc)."""
    if it.has_ground and ground_intersect(it.ground, True, pz, lz, 0.0) < np.inf:
        return 0.0, 0
    tr = 1.0
    tmin = 0.0
    rays = 0
    for _layer in range(it.max_layers):
        h = mesh_intersect(it.mesh, px, py, pz, lx, ly, lz, tmin, np.inf)
        rays += 1
        if h.tri < 0:
            break
        tr *= 1.0 - layer_alpha(it, h.tri, h.b1, h.b2, h.t, px, py, pz, lx, ly, lz, l0, l1, fl)
        if tr <= 0.0:
            return 0.0, rays
        tmin = h.t + it.eps
    return tr, rays


@njit(cache=True)
def quadrature_f1(it, f, ia, ib, two, vx, vy, vz):
    """sum_j (2 pi / L) L_light(l_j) f_1(l_j, v) over the light grid (and its mirror below the surface when the
    table answers light from there: ``lower``), the environment maps (constant lights: ``sky_f1``; SG lights:
    ``sg_f1``), for texel rows ia and (when ``two``) ib: (a r, a g, a b, b r, b g, b b)."""
    lights = it.lights.lights
    ld = it.light_dirs
    n = ld.shape[0]
    dw = 2.0 * math.pi / n   # each grid direction's solid angle
    w = np.empty(3)
    s = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for jj in range(2 * n if it.lower else n):
        j = jj % n
        lx = ld[j, 0]
        ly = ld[j, 1]
        lz = ld[j, 2] if jj < n else -ld[j, 2]
        w[0] = lx * f.tx + ly * f.bx + lz * f.nx
        w[1] = lx * f.ty + ly * f.by + lz * f.ny
        w[2] = lx * f.tz + ly * f.bz + lz * f.nz
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
        for k in range(lights.shape[0]):
            if lights[k, 0] != DIRECTIONAL and lights[k, 0] != SG and lights[k, 0] != CONSTANT:   # sg_f1, sky
                q0, q1, q2 = light_eval(lights, k, it.lights.env, it.lights.marginal, it.lights.conditional, w)
                r0 += q0
                r1 += q1
                r2 += q2
        if r0 == 0.0 and r1 == 0.0 and r2 == 0.0:
            continue
        r0 *= dw
        r1 *= dw
        r2 *= dw
        s = add_f1(s, it, ia, ib, two, lx, ly, lz, vx, vy, vz, r0, r1, r2)
    return s


@njit(cache=True, parallel=True)
def sky_table(texels, light_dirs, view_dirs):
    """(N, V, 3) float32: per texel row and grid view v_i (``view_dirs``, the texture's view grid), the light
    grid's quadrature sum_j (2 pi / L) f_1(l_j, v_i) -- the texel's answer to a constant sky of unit radiance.
    A constant light's radiance is the same from every direction, so this sum does not depend on where the
    texel lies on the mesh (its frame), only on the view: ``quadrature_f1`` of a constant light, computed once
    per texel and grid view instead of once per pixel."""
    N = texels.shape[0]
    K = (texels.shape[1] - TEXEL_HEAD) // (3 * LOBE_PARAMS)
    L = light_dirs.shape[0]
    dw = 2.0 * math.pi / L
    out = np.empty((N, view_dirs.shape[0], 3), np.float32)
    for idx in prange(N):
        for i in range(view_dirs.shape[0]):
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for j in range(L):
                f0, f1, f2 = texel_f1_rgb(texels, K, idx, light_dirs[j, 0], light_dirs[j, 1], light_dirs[j, 2],
                                          view_dirs[i, 0], view_dirs[i, 1], view_dirs[i, 2])
                s0 += dw * f0
                s1 += dw * f1
                s2 += dw * f2
            out[idx, i, 0] = s0
            out[idx, i, 1] = s1
            out[idx, i, 2] = s2
    return out


@njit(cache=True, parallel=True)
def tabulated_sky_table(radiance, weights):
    """``sky_table`` of the tabulated model: per texel row and grid view, sum_j w_ij r(l_j, v_i) over the table's own
    light cells, ``weights`` (V, L) their solid angles (2 pi / L on the hemisphere grid; a half-vector cell's solid
    angle over its valid fraction: ``pipeline.renderers.btf.sky_weights``); ``radiance`` (N, V, L, 3)."""
    N, V, L, _ = radiance.shape
    out = np.empty((N, V, 3), np.float32)
    for idx in prange(N):
        for i in range(V):
            for c in range(3):
                acc = 0.0
                for j in range(L):
                    acc += weights[i, j] * radiance[idx, i, j, c]
                out[idx, i, c] = acc
    return out


@njit(cache=True, inline="always")
def sky_f1(it, ia, ib, two, i0, i1, i2, i3, w0, w1, w2, w3):
    """The constant lights' sum_j (2 pi / L) L f_1(l_j, v) for texel rows ia and (when ``two``) ib: the
    ``sky`` table of each row read at the view's grid weights (as T(v)), times the lights' total radiance."""
    L0 = it.sky_radiance[0]
    L1 = it.sky_radiance[1]
    L2 = it.sky_radiance[2]
    a0 = L0 * view_lookup(it.sky, ia, i0, i1, i2, i3, w0, w1, w2, w3, 0)
    a1 = L1 * view_lookup(it.sky, ia, i0, i1, i2, i3, w0, w1, w2, w3, 1)
    a2 = L2 * view_lookup(it.sky, ia, i0, i1, i2, i3, w0, w1, w2, w3, 2)
    if not two:
        return a0, a1, a2, 0.0, 0.0, 0.0
    return (a0, a1, a2, L0 * view_lookup(it.sky, ib, i0, i1, i2, i3, w0, w1, w2, w3, 0),
            L1 * view_lookup(it.sky, ib, i0, i1, i2, i3, w0, w1, w2, w3, 1),
            L2 * view_lookup(it.sky, ib, i0, i1, i2, i3, w0, w1, w2, w3, 2))


@njit(cache=True)
def sg_f1(it, f, k, ia, ib, two, vx, vy, vz):
    """int L_k(l) f_1(l, v) dl of SG light k for texel rows ia (and ib when ``two``): the SG's own
    distribution on a fixed stratified grid of SG_U x SG_V points (``light_sample`` at the cell
    centres), each carrying radiance / pdf = the light's power over the points -- exact in the sharp
    limit (every point at the axis: a directional light of irradiance P), deterministic, and unlike the
    light grid it does not miss a lobe narrower than the grid's spacing."""
    lights = it.lights.lights
    n = SG_U * SG_V
    s = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for i in range(SG_U):
        for j in range(SG_V):
            w, r, g, b, pdf, _delta = light_sample(lights, k, it.lights.env, it.lights.marginal,
                                                   it.lights.conditional, (i + 0.5) / SG_U, (j + 0.5) / SG_V)
            if pdf <= 0.0:
                continue
            lx, ly, lz = to_local(f, w[0], w[1], w[2])
            if lz <= 0.0 and not it.lower:
                continue
            e0 = r / (pdf * n)
            e1 = g / (pdf * n)
            e2 = b / (pdf * n)
            s = add_f1(s, it, ia, ib, two, lx, ly, lz, vx, vy, vz, e0, e1, e2)
    return s


@njit(cache=True, inline="always")
def shade_surface(it, f, tri, t, dx, dy, dz):
    """(front r, g, b, coverage, rays) of the surface hit with frame f: the coverage-weighted radiance
    towards -d and the coverage, both blended over the mip levels (module doc)."""
    lights = it.lights.lights
    table = it.table
    vx, vy, vz = to_local(f, -dx, -dy, -dz)
    pu, pv = f.pu, f.pv
    if it.relief and (it.shading[tri, S_GEOMETRIC] * dx + it.shading[tri, S_GEOMETRIC + 1] * dy
                      + it.shading[tri, S_GEOMETRIC + 2] * dz) < 0.0:   # the front: the texel the ray meets first
        pu, pv = relief_point(it, pu, pv, vx, vy, vz)
    e, pu, pv = texel_exemplar(it, pu, pv)
    if e < 0:       # no exemplar in this block of the tiling: no cloth here
        return 0.0, 0.0, 0.0, 0.0, 0
    i0, i1, i2, i3, w0, w1, w2, w3 = grid_weights(it.n_theta, it.n_phi, vx, vy, vz)
    texel_width = it.shading[tri, S_TEXEL_WIDTH] / math.sqrt(it.exemplar_scale[e, 0] * it.exemplar_scale[e, 1])
    l0, l1, fl = mip_blend(it, footprint(it, t, f.cos_i, dx, dy, dz), texel_width)
    two = fl > 0.0
    ia = texel_index(it.levels, e, l0, pu, pv)
    ib = texel_index(it.levels, e, l1, pu, pv)
    # T(v) and alpha of the (one or two) texels, premultiplied by alpha and their mip weights
    aa = (1.0 - fl) * view_lookup(table, ia, i0, i1, i2, i3, w0, w1, w2, w3, 3)
    ta0 = aa * view_lookup(table, ia, i0, i1, i2, i3, w0, w1, w2, w3, 0)
    ta1 = aa * view_lookup(table, ia, i0, i1, i2, i3, w0, w1, w2, w3, 1)
    ta2 = aa * view_lookup(table, ia, i0, i1, i2, i3, w0, w1, w2, w3, 2)
    ab = 0.0
    tb0 = 0.0
    tb1 = 0.0
    tb2 = 0.0
    if two:
        ab = fl * view_lookup(table, ib, i0, i1, i2, i3, w0, w1, w2, w3, 3)
        tb0 = ab * view_lookup(table, ib, i0, i1, i2, i3, w0, w1, w2, w3, 0)
        tb1 = ab * view_lookup(table, ib, i0, i1, i2, i3, w0, w1, w2, w3, 1)
        tb2 = ab * view_lookup(table, ib, i0, i1, i2, i3, w0, w1, w2, w3, 2)
    cover = aa + ab
    # sums over the lights of E f_1 (a: the texel of level l0, b: of level l1)
    s = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    rays = 0
    if cover > 0.0:
        for k in range(lights.shape[0]):
            if lights[k, 0] == SG:
                s = add6(s, sg_f1(it, f, k, ia, ib, two, vx, vy, vz))
                continue
            if lights[k, 0] != DIRECTIONAL:
                continue
            wx = lights[k, 4]
            wy = lights[k, 5]
            wz = lights[k, 6]
            lx, ly, lz = to_local(f, wx, wy, wz)
            if lz <= 0.0 and not it.lower:
                continue
            vis = 1.0
            if it.shadows:
                # a light behind the surface: the shadow ray leaves from its far side (the table holds the cloth's
                # own shadow); in front, from the near side, as the hit point was moved
                back = 2.0 * it.eps if lz < 0.0 else 0.0
                vis, nr = shadow_transmittance(it, f.px - back * f.nx, f.py - back * f.ny, f.pz - back * f.nz,
                                               wx, wy, wz, l0, l1, fl)
                rays += nr
                if vis <= 0.0:
                    continue
            e0 = lights[k, 1] * vis
            e1 = lights[k, 2] * vis
            e2 = lights[k, 3] * vis
            s = add_f1(s, it, ia, ib, two, lx, ly, lz, vx, vy, vz, e0, e1, e2)
        if it.has_sky:
            s = add6(s, sky_f1(it, ia, ib, two, i0, i1, i2, i3, w0, w1, w2, w3))
        if it.env_lights > 0:
            s = add6(s, quadrature_f1(it, f, ia, ib, two, vx, vy, vz))
    return ta0 * s[0] + tb0 * s[3], ta1 * s[1] + tb1 * s[4], ta2 * s[2] + tb2 * s[5], min(max(cover, 0.0), 1.0), rays


@njit(cache=True)
def shade_ground(it, t, ox, oy, oz, dx, dy, dz):
    """(r, g, b, rays) leaving the Lambertian ground plane at o + t d towards -d: directional lights
    (shadowed through the mesh when ``shadows``) and the light-grid quadrature of the others."""
    lights = it.lights.lights
    s = 1.0 if dz < 0.0 else -1.0      # the side of the plane the ray comes from
    px = ox + t * dx
    py = oy + t * dy
    pz = oz + t * dz + s * it.eps
    a0 = it.ground[1] * INV_PI
    a1 = it.ground[2] * INV_PI
    a2 = it.ground[3] * INV_PI
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    rays = 0
    for k in range(lights.shape[0]):
        if lights[k, 0] != DIRECTIONAL:
            continue
        c = s * lights[k, 6]
        if c <= 0.0:
            continue
        vis = 1.0
        if it.shadows:
            vis, nr = shadow_transmittance(it, px, py, pz, lights[k, 4], lights[k, 5], lights[k, 6], 0, 0, 0.0)
            rays += nr
        L0 += lights[k, 1] * vis * c * a0
        L1 += lights[k, 2] * vis * c * a1
        L2 += lights[k, 3] * vis * c * a2
    if it.quad_lights > 0:
        ld = it.light_dirs
        dw = 2.0 * math.pi / ld.shape[0]
        w = np.empty(3)
        for j in range(ld.shape[0]):
            w[0] = ld[j, 0]
            w[1] = s * ld[j, 1]
            w[2] = s * ld[j, 2]
            c = ld[j, 2] * dw
            for k in range(lights.shape[0]):
                if lights[k, 0] != DIRECTIONAL:
                    q0, q1, q2 = light_eval(lights, k, it.lights.env, it.lights.marginal, it.lights.conditional, w)
                    L0 += q0 * c * a0
                    L1 += q1 * c * a1
                    L2 += q2 * c * a2
    return L0, L1, L2, rays


@njit(cache=True, inline="always")
def btf_radiance(it, o, d):
    """``PathSample`` of the camera ray (o, d): surfaces front to back with their coverage (module doc)."""
    ox = o[0]
    oy = o[1]
    oz = o[2]
    dx = d[0]
    dy = d[1]
    dz = d[2]
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    thr = 1.0
    first_t = 0.0
    rays = 0
    tmin = 0.0
    for layer in range(it.max_layers + 1):
        if layer < it.max_layers:
            h = mesh_intersect(it.mesh, ox, oy, oz, dx, dy, dz, tmin, np.inf)
            rays += 1
        else:   # surfaces beyond the last layer are not seen
            h = TriangleHit(np.inf, -1, 0.0, 0.0)
        th = h.t
        tg = ground_intersect(it.ground, it.has_ground, oz, dz, tmin)
        if tg < th:
            g0, g1, g2, nr = shade_ground(it, tg, ox, oy, oz, dx, dy, dz)
            if layer == 0:
                first_t = tg
            return PathSample(L0 + thr * g0, L1 + thr * g1, L2 + thr * g2, 1.0, first_t, 0, rays + nr)
        if th == np.inf:
            e0, e1, e2 = environment_radiance(it.lights.lights, it.lights.env, it.lights.marginal,
                                              it.lights.conditional, d)
            return PathSample(L0 + thr * e0, L1 + thr * e1, L2 + thr * e2, 1.0 if layer > 0 else 0.0,
                              first_t, 0, rays)
        if layer == 0:
            first_t = th
        f = surface_frame(it.shading, h.tri, h.b1, h.b2, th, ox, oy, oz, dx, dy, dz, it.eps)
        c0, c1, c2, cover, nr = shade_surface(it, f, h.tri, th, dx, dy, dz)
        rays += nr
        L0 += thr * c0
        L1 += thr * c1
        L2 += thr * c2
        thr *= 1.0 - cover
        if thr <= 0.0:
            break
        tmin = th + it.eps
    return PathSample(L0, L1, L2, 1.0, first_t, 0, rays)


@overload(radiance, inline="always")
def _btf_radiance(integ, o, d, seed, index):
    if is_tuple_class(integ, BtfIntegrator):
        return lambda integ, o, d, seed, index: btf_radiance(borrowed(integ), o, d)
