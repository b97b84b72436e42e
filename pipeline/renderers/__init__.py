"""Render methods: one module per method (``<method>.py``), each defining

    render(scene: pipeline.scene.Scene, options: dict) -> RenderResult

``options`` holds the command line's settings: ``width``, ``height``, ``spp``, ``seed`` (already resolved
against the scene's camera and [render] table), ``source`` (the command line's value only, None when not
given: a method falls back to the scene's ``render.source`` where that applies), ``fibers``, ``bcsdf``, ``material``,
``max_depth``, ``rr_depth``, ``threads`` and any ``--set key=value`` pairs (strings) under ``extra``.
A renderer returns linear RGB (H, W, 3) float32, optional extra channels (name -> (H, W) float32, e.g.
``A``, ``depth``, ``variance``) and ``stats``: at least ``rays`` (rays or ray steps traced), ``paths``
(camera samples), ``render_s`` (seconds spent in the kernels). ``loomlight render`` turns these into
the EXR, the PNG preview and the ``render`` artifact.
"""
from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass, field

import numpy as np

from ..errors import LoomError


@dataclass
class RenderResult:
    rgb: np.ndarray
    extra: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


def known_methods() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def renderer(method: str):
    """The module implementing ``method``; unknown methods raise a LoomError listing the known ones."""
    known = known_methods()
    if method not in known:
        raise LoomError(None, "--method", f"unknown render method {method!r} (known: {', '.join(known)})")
    return importlib.import_module(f"{__name__}.{method}")
