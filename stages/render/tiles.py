"""The tile loop every render method shares: camera samples, the integrator, the film, threads.

``render_tile(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film, row_off, miss, redo)`` (or
``render_tile_borrowed``, the same compiled without reference counting; ``tile_kernel(integ)`` picks) renders
pixels [row0, row1) x [col0, col1): pixel (row, col) takes the ``counts[row - row_off, col]`` samples s = first,
first + 1, ...; camera sample ``index = (row W + col) stride + s`` jitters its position inside the
pixel with ``uniform(seed, index, 0)`` and ``uniform(seed, index, 1)`` (a box filter,
``stages.render.film``), traces the camera ray (``stages.render.camera``) with the integrator's
``radiance`` (``stages.render.integrator``) and stores the pixel's sums (a pixel with no samples
is left as it is) in ``film[row - row_off, col]``: ``counts`` and ``film`` may be a band of the image's
rows starting at ``row_off`` (a chunk task renders one band) or the whole image (``row_off`` 0). ``stride``
bounds every pixel's sample numbers, so indices never collide; a plain render has stride = first + counts = spp.
It is compiled once per integrator class and releases the GIL; calling it on an empty tile compiles (or loads)
it without rendering (``load_tile_kernel``). ``miss`` ((1,) int64) and ``redo`` (uint8, shaped as ``counts``):
where a lookup of a pixel's paths raised ``miss`` (paged procedural tables whose yarn's frame samples were
not resident: ``stages.core.yarn.frame_pool``), the pixel is marked in ``redo``; a render that pages
nothing passes ``no_redo()``.

``render_tiles(integ, cam, seed, stride, first, counts, tiles, film, threads)`` renders rows of
``tile_grid`` on ``threads`` threads (default: numba's thread count), one GIL-free ``render_tile``
call per tile. With a ``pager`` (paged procedural tables) it renders in rounds: the pixels marked in ``redo``
take all their samples again once the yarns their lookups wanted are paged in.
Every pixel depends only on its own random numbers, so the film is the same whatever the thread
count or order. (Threads rather than ``prange``: numba's parallel loops cannot take integrators
that nest namedtuples of namedtuples, such as the procedural tables inside a medium.)
"""
import threading

import numpy as np
from numba import njit

from stages.core.geometry.stack import stack_vector3
from stages.core.rng import uniform
from stages.render.camera import CAM_WIDTH, camera_ray_into
from stages.render.film import add_pixel
from stages.render.integrator import radiance


@njit(cache=True, inline="always")
def _render_pixels(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film, row_off, miss, redo):
    """``render_tile``'s loop over the tile's pixels and their samples.
    14 parameters: ``render_tile``'s."""
    W = int(cam[CAM_WIDTH])
    o = stack_vector3()   # the camera ray, refilled per sample (integrators may move it along the path)
    d = stack_vector3()
    for row in range(row0, row1):
        for col in range(col0, col1):
            n = counts[row - row_off, col]
            if n <= 0:
                continue
            pix = row * W + col
            missed = miss[0]
            sr = 0.0
            sg = 0.0
            sb = 0.0
            srr = 0.0
            sgg = 0.0
            sbb = 0.0
            sy = 0.0
            syy = 0.0
            sh = 0.0
            sd = 0.0
            sl = 0.0
            sn = 0.0
            for s in range(first, first + n):
                index = pix * stride + s
                camera_ray_into(cam, row, col, uniform(seed, index, 0), uniform(seed, index, 1), o, d)
                ps = radiance(integ, o, d, seed, index)
                sr += ps.r
                sg += ps.g
                sb += ps.b
                srr += ps.r * ps.r
                sgg += ps.g * ps.g
                sbb += ps.b * ps.b
                y = 0.2126 * ps.r + 0.7152 * ps.g + 0.0722 * ps.b
                sy += y
                syy += y * y
                sh += ps.hit
                sd += ps.depth
                sl += ps.lookups
                sn += ps.rays
            add_pixel(film, row - row_off, col, sr, sg, sb, srr, sgg, sbb, sy, syy, sh, sd, sl, sn)
            if miss[0] != missed:   # a lookup of this pixel's paths could not answer yet (paged tables)
                redo[row - row_off, col] = 1


@njit(cache=True, nogil=True)
def render_tile(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film, row_off, miss, redo):
    """The tile loop (module doc).
    14 parameters: the integrator and camera, the random stream and sample numbers, the tile, the film and its
    first row, and the paged tables' miss counter and the pixels to render again (``render_tiles``)."""
    _render_pixels(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film, row_off, miss, redo)


@njit(cache=True, nogil=True, _nrt=False)
def render_tile_borrowed(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film, row_off, miss, redo):
    """``render_tile`` compiled without reference counting, for integrators whose kernels take no
    references (``integ.reference_free``): passing the integrator's arrays down costs no atomic
    reference-count updates per sample (with two threads on the same arrays those dominated fiberpath's
    shading).
    14 parameters: ``render_tile``'s."""
    _render_pixels(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film, row_off, miss, redo)


def tile_kernel(integ):
    """The compiled tile loop for this integrator: ``render_tile_borrowed`` when its class says
    ``reference_free``, else ``render_tile``. Calling it on an empty tile compiles (or loads) it
    (``load_tile_kernel``)."""
    return render_tile_borrowed if getattr(integ, "reference_free", False) else render_tile


def no_redo():
    """(miss, redo) for a render that pages nothing: a miss counter no lookup counts in, no pixel to redo."""
    return np.zeros(1, np.int64), np.zeros((1, 1), np.uint8)


def load_tile_kernel(integ, cam, seed=0, stride=1):
    """Compile (or load from numba's cache) this integrator's tile loop by calling it on an empty tile."""
    from stages.render.film import new_film

    tile_kernel(integ)(integ, cam, int(seed), int(stride), 0, np.zeros((1, 1), np.int64), 0, 0, 0, 0, new_film(1, 1),
                       0, *no_redo())


def _nothing(n):
    pass


def _round(tile, integ, args, tiles, film, row_off, n, pager, copies, redo, done):
    """Render ``tiles`` once on ``n`` threads; with a pager, each thread's integrator counts its lookups'
    misses in its own array and the tile loop marks the pixels whose paths missed in ``redo``."""
    def one(t):
        if pager is None:
            tile(integ, *args, t[0], t[1], t[2], t[3], film, row_off, *no_redo())
            return
        me = threading.get_ident()
        if me not in copies:
            miss = np.zeros(1, np.int64)
            copies[me] = (miss, pager.with_miss(integ, miss))
        miss, ig = copies[me]
        tile(ig, *args, t[0], t[1], t[2], t[3], film, row_off, miss, redo)

    if n <= 1 or len(tiles) <= 1:
        for t in tiles:
            one(t)
            done(1)
    else:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=n) as ex:
            for _ in ex.map(one, tiles):
                done(1)


def render_tiles(integ, cam, seed, stride, first, counts, tiles, film, threads=None, row_off=0, pager=None,
                 advance=None):
    """Render the tiles (rows of (row0, col0, row1, col1)) into ``film``; returns it. ``counts``: an
    int array of samples per pixel shaped as ``film``'s first two axes (or an int: every pixel);
    both hold the image's rows from ``row_off`` on. ``pager``: a ``stages.core.yarn.frame_pool.FramePool``
    whose tables ``integ`` holds: rendered in rounds, each pixel whose lookups missed a yarn's frame samples
    again (all its samples) once they are paged in; its sums are overwritten, so the film is the one the
    resident tables give. ``advance(n)``: called as the first round finishes tiles (a progress bar)."""
    import numba

    n = int(threads or numba.get_num_threads())
    tiles = np.asarray(tiles, np.int64).reshape(-1, 4)
    if np.ndim(counts) == 0:
        counts = np.full(film.shape[:2], int(counts), np.int64)
    counts = np.ascontiguousarray(counts, np.int64)
    tile = tile_kernel(integ)
    copies = {}
    while len(tiles):
        redo = np.zeros(counts.shape, np.uint8)
        _round(tile, integ, (cam, int(seed), int(stride), int(first), counts), tiles, film, int(row_off), n, pager,
               copies, redo, advance or _nothing)
        advance = None
        if pager is None or not redo.any():
            break
        pager.pixels_again += int(np.count_nonzero(redo))
        pager.page_in()
        counts = np.where(redo != 0, counts, 0)
        tiles = tiles[[bool(redo[t[0] - row_off:t[2] - row_off, t[1]:t[3]].any()) for t in tiles]]
    return film
