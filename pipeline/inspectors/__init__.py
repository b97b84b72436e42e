"""Pictures of intermediate artifacts, one module per artifact kind (``<kind>.py``).

Each module defines ``inspect(artifact, png, show=False, **options)`` and draws with pyvista
off-screen (or matplotlib for plots). ``pyvista_setup`` chooses an off-screen backend that works.
"""
from __future__ import annotations

import importlib
import os

from ..errors import LoomError


def pyvista_setup():
    """Import pyvista configured for off-screen rendering (EGL where available)."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista


def inspector_for(kind: str):
    try:
        return importlib.import_module(f"{__name__}.{kind}")
    except ModuleNotFoundError:
        raise LoomError(None, None, f"no inspector for artifacts of kind {kind!r}") from None
