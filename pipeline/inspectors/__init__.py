"""Pictures of intermediate artifacts, one module per artifact kind (``<kind>.py``).

Each module defines ``inspect(artifact, png, show=False, **options)``. Pictures are matplotlib
figures: every panel has a title, every colour coding a legend or a colour bar, and no text is
smaller than ``MIN_FONT_PT`` points at the saved resolution (``DPI``). Three-dimensional views are
drawn by pyvista off-screen (``pyvista_setup``), cropped to their content (``screenshot``) and placed
into a matplotlib panel (with ``--show`` the pyvista window opens instead, for turning the view).
"""
from __future__ import annotations

import contextlib
import importlib
import os

import numpy as np

from ..errors import LoomError

DPI = 100            # pixels per inch of the saved PNG: ``--width`` x ``--height`` pixels = size / DPI inches
MIN_FONT_PT = 9      # the smallest text anywhere in a picture, in points at DPI
STYLE = {"font.size": 10, "axes.titlesize": 10.5, "axes.labelsize": 10, "xtick.labelsize": 9,
         "ytick.labelsize": 9, "legend.fontsize": 9, "legend.title_fontsize": 9, "figure.titlesize": 11.5,
         "figure.dpi": DPI, "savefig.dpi": DPI, "figure.facecolor": "white", "savefig.facecolor": "white"}


def pyvista_setup():
    """Import pyvista configured for off-screen rendering (EGL where available)."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista


@contextlib.contextmanager
def pyplot(show: bool = False):
    """matplotlib.pyplot (the Agg backend unless ``show``) with the inspectors' style in force:
    create and save the figure inside the ``with``."""
    import matplotlib

    if not show:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with plt.rc_context(STYLE):
        yield plt


def finish(fig, png, show: bool = False, tight: bool = True):
    """Save ``fig`` to ``png`` (within the figure's size, cut to its content when ``tight``: no empty
    margins), show it if asked, close it."""
    import io

    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    if png is not None:
        if tight:
            buf = io.BytesIO()
            fig.savefig(buf, dpi=DPI, format="png")
            buf.seek(0)
            img = (np.asarray(mpimg.imread(buf, format="png"))[..., :3] * 255).round().astype(np.uint8)
            mpimg.imsave(str(png), np.ascontiguousarray(crop_to_content(img, (255, 255, 255), pad=6)))
        else:
            fig.savefig(str(png), dpi=DPI)
    if show:
        plt.show()
    plt.close(fig)
    return png


def crop_to_content(img: np.ndarray, background=None, pad: int = 4) -> np.ndarray:
    """``img`` (H, W, C) cut to the bounding box of the pixels that differ from ``background`` (default:
    the top-left pixel's colour), with ``pad`` pixels kept around."""
    bg = img[0, 0] if background is None else np.asarray(background, img.dtype)
    diff = np.any(np.abs(img.astype(np.int32) - bg.astype(np.int32)) > 3, axis=-1)
    rows, cols = np.nonzero(diff.any(axis=1))[0], np.nonzero(diff.any(axis=0))[0]
    if len(rows) == 0:
        return img
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, img.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, img.shape[1])
    return img[r0:r1, c0:c1]


def screenshot(plotter) -> np.ndarray:
    """The off-screen plotter's picture (H, W, 3) uint8, cropped to its content; closes the plotter."""
    img = plotter.screenshot(return_img=True)
    plotter.close()
    return crop_to_content(np.asarray(img)[..., :3])


def image_panel(ax, img, title: str) -> None:
    """A 3D view's picture in a panel: no axes, equal aspect, a title."""
    ax.imshow(img, interpolation="lanczos" if min(img.shape[:2]) > 200 else "nearest")
    ax.set_axis_off()
    ax.set_title(title)


def view_with_legend(plotter, size, title: str, handles, legend_title: str, png):
    """A pyvista view cut to its content in a matplotlib panel titled ``title``, with ``handles``
    (matplotlib legend handles) beside it; the figure as tall as the view needs at the width left
    beside the legend (at most ``size[1]``)."""
    img = screenshot(plotter)
    with pyplot() as plt:
        fh = min(size[1] / 100, 0.78 * size[0] / 100 * img.shape[0] / img.shape[1] + 0.5)
        fig, ax = plt.subplots(figsize=(size[0] / 100, fh), layout="constrained")
        image_panel(ax, img, title)
        fig.legend(handles=handles, loc="outside right upper", title=legend_title, frameon=False)
        return finish(fig, png)


def inspector_for(kind: str):
    try:
        return importlib.import_module(f"{__name__}.{kind}")
    except ModuleNotFoundError:
        raise LoomError(None, None, f"no inspector for artifacts of kind {kind!r}") from None
