"""Image output: linear float32 OpenEXR plus an sRGB PNG preview, each written atomically (to a
hidden temporary beside it, then renamed), or into a temporary the caller publishes (``into``: a
render publishes its EXR, PNG and render artifact as one set, ``pipeline.artifacts``)."""
from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import LoomError


def _write_atomic(path: Path, write: Callable[[Path], None], into: Path | None = None) -> Path:
    """``write(tmp)`` to a temporary beside ``path``, then rename it into place; with ``into``, write
    there and leave the publishing to the caller."""
    from .artifacts import temp_sibling

    path.parent.mkdir(parents=True, exist_ok=True)
    if into is not None:
        write(into)
        return into
    tmp = temp_sibling(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def write_exr(path: str | Path, rgb: np.ndarray, extra: dict[str, np.ndarray] | None = None,
              into: Path | None = None) -> Path:
    """Linear RGB (H, W, 3) as float32 OpenEXR (ZIP); ``extra`` adds named single channels (A, depth, ...)."""
    import OpenEXR

    channels = {"RGB": np.ascontiguousarray(rgb, dtype=np.float32)}
    for k, v in (extra or {}).items():
        channels[k] = np.ascontiguousarray(v, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp: Path) -> None:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))

    return _write_atomic(Path(path), write, into)


def read_exr(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(RGB float32 (H, W, 3), other channels by name). Bad files raise a one-line LoomError. A render's
    EXR is published with its PNG and artifact as one set: an interrupted publication of that set is
    settled first (``pipeline.artifacts.settle``), so the EXR read is the one the artifact describes."""
    import OpenEXR

    from .artifacts import settle

    path = Path(path)
    settle(path.with_suffix(".zarr"))
    if not path.exists():
        raise LoomError(path, None, "file not found")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.array(v.pixels) for k, v in f.channels().items()}
    except Exception as e:  # OpenEXR raises plain RuntimeError/OSError for non-EXR input
        raise LoomError(path, None, f"not a readable OpenEXR file ({e})") from None
    if all(k in ch for k in ("R", "G", "B")):
        rgb = np.stack([ch.pop("R"), ch.pop("G"), ch.pop("B")], axis=-1).astype(np.float32)
    elif "Y" in ch:
        y = ch.pop("Y").astype(np.float32)
        rgb = np.stack([y, y, y], axis=-1)
    else:
        raise LoomError(path, None, f"no R, G, B (or Y) channels; found {sorted(ch)}")
    return rgb, ch


def to_srgb8(rgb: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """8-bit sRGB display values of linear RGB times 2^exposure (NaN as 0, +inf as 1, clipped to [0, 1]), by
    ``pipeline.thread_colors.linear_to_srgb`` (IEC 61966-2-1): the same arithmetic as colour-science's
    ``cctf_encoding(..., "sRGB")``, which encoded the previews before (their bytes are unchanged), without
    importing colour-science, whose import takes 3-4 s (its plotting and matplotlib.pyplot) in every command
    that writes a PNG."""
    from .thread_colors import linear_to_srgb

    lin = np.clip(np.nan_to_num(rgb * (2.0 ** exposure), nan=0.0, posinf=1.0), 0.0, 1.0)
    return np.round(np.clip(linear_to_srgb(lin), 0, 1) * 255.0).astype(np.uint8)


PNG_DPI = 100     # the resolution matplotlib's ``imsave`` records by default (its ``dpi=100``)


@functools.cache
def _png_software() -> str:
    """The ``Software`` text chunk matplotlib's ``imsave`` writes, which the previews have always carried (its
    version from the installed package's metadata, without importing it)."""
    from importlib.metadata import version

    return f"Matplotlib version{version('matplotlib')}, https://matplotlib.org/"


def write_png(path: str | Path, img8: np.ndarray, into: Path | None = None) -> Path:
    """8-bit sRGB ``img8`` (H, W, 3) as a PNG, written by Pillow as matplotlib's ``imsave`` wrote the previews
    before (RGBA with opaque alpha, ``PNG_DPI``, its ``Software`` text chunk): the same bytes
    (``tests/pipeline/test_images.py``) without importing matplotlib, half a second of every command that
    writes a render."""
    from PIL import Image, PngImagePlugin

    img8 = np.asarray(img8)
    if img8.dtype != np.uint8 or img8.ndim != 3 or img8.shape[2] != 3:
        raise ValueError(f"write_png takes (H, W, 3) uint8, got {img8.dtype} {img8.shape}")
    rgba = np.empty(img8.shape[:2] + (4,), np.uint8)
    rgba[..., :3] = img8
    rgba[..., 3] = 255
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", _png_software())
    image = Image.frombuffer("RGBA", (rgba.shape[1], rgba.shape[0]), rgba, "raw", "RGBA", 0, 1)
    return _write_atomic(Path(path), lambda tmp: image.save(str(tmp), format="png", dpi=(PNG_DPI, PNG_DPI),
                                                             pnginfo=info), into)


def write_render(exr_path: str | Path, rgb: np.ndarray, extra: dict | None = None, exposure: float = 0.0,
                 into: Callable[[Path], Path] | None = None) -> tuple[Path, Path]:
    """EXR at ``exr_path`` and its sRGB preview beside it (same stem, .png); ``into(final path)`` gives
    the temporaries to write them to instead (the caller publishes them)."""
    exr_path = Path(exr_path)
    png_path = exr_path.with_suffix(".png")
    exr = write_exr(exr_path, rgb, extra, into(exr_path) if into else None)
    png = write_png(png_path, to_srgb8(rgb, exposure), into(png_path) if into else None)
    return exr, png
