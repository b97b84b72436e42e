"""The tile loop every render method shares: camera samples, the integrator, the film, threads.

``render_tile(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film)`` renders pixels
[row0, row1) x [col0, col1): pixel (row, col) takes the ``counts[row, col]`` samples s = first,
first + 1, ...; camera sample ``index = (row W + col) stride + s`` jitters its position inside the
pixel with ``uniform(seed, index, 0)`` and ``uniform(seed, index, 1)`` (a box filter,
``stages.render.film``), traces the camera ray (``stages.render.camera``) with the integrator's
``radiance`` (``stages.render.integrator``) and stores the pixel's sums (a pixel with no samples
is left as it is). ``stride`` bounds every pixel's sample numbers, so indices never collide; a plain
render has stride = first + counts = spp. It is compiled once per integrator class and releases
the GIL; calling it on an empty tile compiles (or loads) it without rendering.

``render_tiles(integ, cam, seed, stride, first, counts, tiles, film, threads)`` renders rows of
``tile_grid`` on ``threads`` threads (default: numba's thread count), one GIL-free ``render_tile``
call per tile.
Every pixel depends only on its own random numbers, so the film is the same whatever the thread
count or order. (Threads rather than ``prange``: numba's parallel loops cannot take integrators
that nest namedtuples of namedtuples, such as the procedural tables inside a medium.)
"""
import numpy as np
from numba import njit

from stages.core.rng import uniform
from stages.render.camera import camera_ray
from stages.render.film import add_pixel
from stages.render.integrator import radiance


@njit(cache=True, nogil=True)
def render_tile(integ, cam, seed, stride, first, counts, row0, col0, row1, col1, film):
    W = int(cam[13])
    for row in range(row0, row1):
        for col in range(col0, col1):
            n = counts[row, col]
            if n <= 0:
                continue
            pix = row * W + col
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
                o, d = camera_ray(cam, row, col, uniform(seed, index, 0), uniform(seed, index, 1))
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
            add_pixel(film, row, col, sr, sg, sb, srr, sgg, sbb, sy, syy, sh, sd, sl, sn)


def render_tiles(integ, cam, seed, stride, first, counts, tiles, film, threads=None):
    """Render the tiles (rows of (row0, col0, row1, col1)) into ``film``; returns it. ``counts``: an
    (H, W) int array of samples per pixel (or an int: every pixel)."""
    import numba

    n = int(threads or numba.get_num_threads())
    tiles = np.asarray(tiles, np.int64).reshape(-1, 4)
    if np.ndim(counts) == 0:
        counts = np.full(film.shape[:2], int(counts), np.int64)
    args = (integ, cam, int(seed), int(stride), int(first), np.ascontiguousarray(counts, np.int64))
    if n <= 1 or len(tiles) <= 1:
        for t in tiles:
            render_tile(*args, t[0], t[1], t[2], t[3], film)
        return film
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n) as ex:
        list(ex.map(lambda t: render_tile(*args, t[0], t[1], t[2], t[3], film), tiles))
    return film
