"""Thread colours: where each yarn's colour comes from, sRGB <-> linear, and the line ``info`` shows.

A yarn's colour is decided once, at ingest (``pipeline.runners.ingest``), and recorded per yarn in
the ``yarns`` artifact as ``color`` (linear RGB) and ``color_source`` (an index into
``COLOR_SOURCES``):

- ``scene`` (2): the scene sets the yarn group's colour (``yarns.<group>.color``, or
  ``yarns.default.color``). It wins over everything else.
- ``draft`` (1): the input file gives the thread a colour (a WIF draft's ``[WARP COLORS]`` /
  ``[WEFT COLORS]`` entry or ``[WARP]`` / ``[WEFT]`` ``Color``, ``pipeline.io.wif``).
- ``yarn type`` (0): neither: the yarn type's albedo (its preset's), resolved where the preset is,
  by tables / realize (``pipeline.runners.yarn_types``). ``color`` then holds only the group colour
  the yarns inspector draws.

Later stages read the colour of a ``draft`` yarn from ``color`` and every other yarn's from its yarn
type (which carries the scene's colour), so all methods agree (docs/wif-colours.md). A tiling
records its exemplar yarns' draft colours the same way (``ex_yarn_color``, ``ex_yarn_color_source``).

Colours in a WIF are display values (sRGB-encoded); loomlight renders linear RGB, so they are decoded
with the sRGB transfer function (IEC 61966-2-1) when read, and encoded again only for display
(``srgb_hex``).
"""
from __future__ import annotations

import numpy as np

COLOR_SOURCES = ("yarn type", "draft", "scene")
FROM_TYPE, FROM_DRAFT, FROM_SCENE = 0, 1, 2


def srgb_to_linear(c):
    """sRGB-encoded values in [0, 1] -> linear (IEC 61966-2-1 decoding)."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c):
    """Linear values in [0, 1] -> sRGB-encoded (the inverse of ``srgb_to_linear``)."""
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)


def srgb_hex(linear) -> str:
    """``#rrggbb`` of a linear colour: its 8-bit sRGB display value (a WIF colour of range 0..255 comes
    back as the draft's own numbers)."""
    r, g, b = (int(round(float(x) * 255.0)) for x in linear_to_srgb(linear))
    return f"#{r:02x}{g:02x}{b:02x}"


def describe_group(group: str, colors, sources) -> str:
    """One line of a group's thread colours, e.g. ``24 threads, 2 colours from the draft: #c01020 x12,
    #ffffff x12`` (threads for warp and weft, yarns otherwise); counts in order of first appearance."""
    colors = np.asarray(colors, np.float64).reshape(-1, 3)
    sources = np.asarray(sources, np.int64).reshape(-1)
    unit = "thread" if group in ("warp", "weft") else "yarn"
    n = len(sources)
    parts = []
    for src in (FROM_DRAFT, FROM_SCENE):
        counts: dict[str, int] = {}
        for c in colors[sources == src]:
            h = srgb_hex(c)
            counts[h] = counts.get(h, 0) + 1
        if counts:
            what = "from the draft" if src == FROM_DRAFT else "from the scene"
            parts.append(f"{len(counts)} colour{'s' if len(counts) != 1 else ''} {what}: "
                         + ", ".join(f"{h} \u00d7{k}" for h, k in counts.items()))
    k = int(np.sum(sources == FROM_TYPE))
    if k:
        parts.append(f"{k} {unit}{'s' if k != 1 else ''} in the yarn type's colour (its preset's albedo)")
    return f"{n} {unit}{'s' if n != 1 else ''}, " + "; ".join(parts)


def describe(group_names, group, colors, sources) -> dict:
    """{group name: ``describe_group`` line} for every group present (``group`` (Y,) indices into
    ``group_names``): the ``thread_colors`` entry of a yarns artifact's summary."""
    group = np.asarray(group)
    return {name: describe_group(name, np.asarray(colors)[group == g], np.asarray(sources)[group == g])
            for g, name in enumerate(group_names) if np.any(group == g)}
