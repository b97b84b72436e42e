"""Run the shared tile loop (``stages.render.tiles``) over an image with a progress bar.

``render_film(label, integ, cam, width, height, spp, seed, tile_size, variance, threads)`` renders
the image in batches of tiles (one progress step per tile) and finishes the film
(``stages.render.film.finalize``): returns (rgb, extra channels ``A``/``depth``/``variance``,
``FilmImage`` with the ray and lookup totals, render seconds).
"""
from __future__ import annotations

import os
import time

from ..progress import progress


def render_film(label, integ, cam, width, height, spp, seed, tile_size, variance, threads=None):
    from stages.render.film import finalize, new_film, tile_grid
    from stages.render.tiles import render_tiles

    tiles = tile_grid(width, height, int(tile_size))
    film = new_film(width, height)
    batch = max(1, 4 * (os.cpu_count() or 1))
    t0 = time.perf_counter()
    with progress(f"{label} {width}x{height} @ {spp} spp", len(tiles)) as advance:
        for b0 in range(0, len(tiles), batch):
            b1 = min(b0 + batch, len(tiles))
            render_tiles(integ, cam, seed, spp, tiles[b0:b1], film, threads)
            advance(b1 - b0)
    render_s = time.perf_counter() - t0
    img = finalize(film, spp, variance)
    extra = {"A": img.alpha, "depth": img.depth, "variance": img.variance}
    return img.rgb, extra, img, render_s
