"""What the tile stage lays its exemplars on: the block map and the base surface.

``block_map`` resolves ``[tiling] block_map`` (a PNG or an integer array, with ``map_values``)
to the exemplar of every block of the (nbu, nbv) block grid, resampled nearest. ``build_surface``
makes the ``[surface]`` mesh (V, UV, F): a flat rectangle, a cylinder, a sphere drape
(``stages.tile.base_surfaces``) or an OBJ mesh with uv (``pipeline.io.obj_mesh``), scaled and offset.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import LoomError


def _read_png_map(path, file):
    from PIL import Image

    p = Path(path)
    if not p.exists():
        raise LoomError(file, "tiling.block_map", f"block map image not found: {p}")
    try:
        img = np.asarray(Image.open(p))
    except Exception as e:  # PIL raises many types for unreadable images
        raise LoomError(p, None, f"unreadable block map image: {e}") from None
    if img.ndim == 3:
        img = img[..., 0]
    return img.astype(np.int64)


def block_map(cfg, file, K, nbu, nbv):
    """(nbu, nbv) int32: exemplar of block (i, j) (i along u, j along v)."""
    t = cfg.get("tiling", {})
    src = t.get("block_map")
    if src is None:
        return np.zeros((nbu, nbv), np.int32)
    img = _read_png_map(src, file) if isinstance(src, str) else None
    if img is None:
        rows = src
        if len({len(r) for r in rows}) != 1:
            raise LoomError(file, "tiling.block_map", "rows of the block map differ in length")
        img = np.asarray(rows, np.int64)
    values = t.get("map_values")
    if values is not None:
        lut = {int(v): i for i, v in enumerate(values)}
        bad = sorted(set(np.unique(img).tolist()) - set(lut))
        if bad:
            raise LoomError(file, "tiling.block_map", f"map value {bad[0]} is not listed in tiling.map_values")
        img = np.vectorize(lambda v: lut[int(v)])(img)
    if img.min() < 0 or img.max() >= K:
        badv = int(img.max()) if img.max() >= K else int(img.min())
        raise LoomError(file, "tiling.block_map", f"names exemplar {badv}, but only {K} exemplar(s) "
                                                  f"(0..{K - 1}) are defined")
    from stages.tile.tiling import resample_block_map

    return resample_block_map(img, nbu, nbv)


def build_surface(cfg, file, flat_size):
    from stages.tile import base_surfaces as bs

    from ..io.obj_mesh import read_obj_mesh

    s = cfg["surface"]
    kind = s["kind"]
    res = s.get("resolution")
    if kind == "flat":
        w, h = s.get("size", flat_size)
        nu, nv = res or (8, 8)
        V, UV, F = bs.flat_rectangle(w, h, nu, nv)
    elif kind == "cylinder":
        r = s.get("radius", flat_size[0] / math.pi)
        V, UV, F = bs.cylinder(r, s.get("length", flat_size[1]), s.get("angle", math.degrees(flat_size[0] / r)),
                               *(res or (32, 8)))
    elif kind == "drape":
        size = s.get("size", [max(flat_size)] * 2)[0]
        V, UV, F = bs.sphere_drape(size, s.get("sphere_radius", size / 4), *(res or (32, 32)),
                                   folds=s.get("folds", 6), fold_amplitude=s.get("fold_amplitude", 0.15))
    else:
        if "path" not in s:
            raise LoomError(file, "surface.path", "surface kind 'obj' needs a path")
        V, UV, F, _ = read_obj_mesh(s["path"], file)
    V = V * s.get("scale", 1.0) + np.asarray(s.get("offset", [0.0, 0.0, 0.0]))
    return V, UV, F
