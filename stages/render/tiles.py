"""The tile loop every render method shares: camera samples, the integrator, the film, threads.

``render_tile(integ, cam, seed, spp, row0, col0, row1, col1, film)`` renders pixels [row0, row1) x
[col0, col1): for each pixel and sample s, camera sample ``index = (row W + col) spp + s`` jitters its
position inside the pixel with ``uniform(seed, index, 0)`` and ``uniform(seed, index, 1)`` (a box
filter, ``stages.render.film``), traces the camera ray (``stages.render.camera``) with the
integrator's ``radiance`` (``stages.render.integrator``) and adds the result to the pixel's sums.
It is compiled once per integrator class and releases the GIL.

``render_tiles(integ, cam, seed, spp, tiles, film, threads)`` renders rows of ``tile_grid`` on
``threads`` threads (default: numba's thread count), one GIL-free ``render_tile`` call per tile.
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
def render_tile(integ, cam, seed, spp, row0, col0, row1, col1, film):
    W = int(cam[13])
    for row in range(row0, row1):
        for col in range(col0, col1):
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
            for s in range(spp):
                index = pix * spp + s
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


def render_tiles(integ, cam, seed, spp, tiles, film, threads=None):
    """Render the tiles (rows of (row0, col0, row1, col1)) into ``film``; returns it."""
    import numba

    n = int(threads or numba.get_num_threads())
    tiles = np.asarray(tiles, np.int64).reshape(-1, 4)
    args = (integ, cam, int(seed), int(spp))
    if n <= 1 or len(tiles) <= 1:
        for t in tiles:
            render_tile(*args, t[0], t[1], t[2], t[3], film)
        return film
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n) as ex:
        list(ex.map(lambda t: render_tile(*args, t[0], t[1], t[2], t[3], film), tiles))
    return film
