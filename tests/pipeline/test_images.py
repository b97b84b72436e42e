"""sRGB previews (``pipeline.images.to_srgb8``, ``pipeline.thread_colors.linear_to_srgb``): the encoding
against the reference implementation and the standard's numbers, and what writing one costs a command.

- ``to_srgb8`` against colour-science's ``cctf_encoding(..., "sRGB")`` (the implementation the previews were
  encoded with before; exact equality of the 8-bit values on a dense sweep, float32 and float64, exposures,
  NaN and infinities), and ``linear_to_srgb`` against it exactly in float64;
- IEC 61966-2-1's breakpoint: both branches meet at 0.0031308 (to 1e-7), 0.18 encodes to 0.46135613;
- the decoding is the encoding's inverse (round trip to 1e-12);
- ``write_png`` against matplotlib's ``imsave`` (which wrote the previews before): the same bytes for images of
  random, constant and extreme values and odd sizes;
- a process that writes an EXR and its PNG imports neither colour-science nor matplotlib (3-4 s of imports a
  command, then 0.5 s: measured 7.7 -> 5.5 s for a 16 x 12 fiberpath render from the command line, and a 32 x 24
  bysdf render 4.0 s of which 0.53 s importing matplotlib.image).
"""
import subprocess
import sys

import numpy as np

from pipeline.images import to_srgb8, write_png
from pipeline.thread_colors import linear_to_srgb, srgb_to_linear
from tests.helpers import ROOT


def _colour_srgb8(rgb, exposure=0.0):
    import colour

    lin = np.clip(np.nan_to_num(rgb * (2.0 ** exposure), nan=0.0, posinf=1.0), 0.0, 1.0)
    return np.round(np.clip(colour.cctf_encoding(lin, function="sRGB"), 0, 1) * 255.0).astype(np.uint8)


def test_encoding_equals_colour_science():
    import colour

    rng = np.random.default_rng(3)
    for dtype in (np.float32, np.float64):
        for scale in (1e-3, 1.0, 3.0):
            rgb = (rng.random((64, 48, 3)) * scale).astype(dtype)
            rgb[0, 0] = [np.nan, np.inf, -1.0]
            rgb[0, 1] = [0.0031308, np.nextafter(0.0031308, 0.0), np.nextafter(0.0031308, 1.0)]
            for exposure in (0.0, 1.5, -2.0):
                assert np.array_equal(to_srgb8(rgb, exposure), _colour_srgb8(rgb, exposure)), (dtype, scale, exposure)
    sweep = np.linspace(0.0, 1.0, 400_001)
    assert np.array_equal(linear_to_srgb(sweep), colour.cctf_encoding(sweep, function="sRGB"))
    ramp = np.repeat(sweep.astype(np.float32)[:, None, None], 3, axis=2)
    assert np.array_equal(to_srgb8(ramp), _colour_srgb8(ramp))


def test_standard_values_and_round_trip():
    knee = 0.0031308
    assert abs(12.92 * knee - (1.055 * knee ** (1 / 2.4) - 0.055)) < 1e-7
    assert abs(float(linear_to_srgb(0.18)) - 0.46135613) < 1e-8
    assert float(linear_to_srgb(-1.0)) == 0.0 and abs(float(linear_to_srgb(2.0)) - 1.0) < 1e-15
    v = np.linspace(0.0, 1.0, 10_001)
    assert np.max(np.abs(linear_to_srgb(srgb_to_linear(v)) - v)) < 1e-12
    assert to_srgb8(np.full((1, 1, 3), 0.18, np.float32))[0, 0, 0] == 118


def test_png_bytes_equal_matplotlibs(tmp_path):
    import matplotlib.image as mpimg

    rng = np.random.default_rng(5)
    images = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), np.zeros((1, 1, 3), np.uint8),
              np.full((7, 3, 3), 255, np.uint8), to_srgb8(rng.random((31, 17, 3)) * 2.0)]
    for k, img in enumerate(images):
        ours = write_png(tmp_path / f"ours{k}.png", img)
        theirs = tmp_path / f"theirs{k}.png"
        mpimg.imsave(str(theirs), img, format="png")
        assert ours.read_bytes() == theirs.read_bytes(), img.shape
    for bad in (np.zeros((4, 4), np.uint8), np.zeros((4, 4, 4), np.uint8), np.zeros((4, 4, 3), np.float32)):
        try:
            write_png(tmp_path / "bad.png", bad)
        except ValueError:
            continue
        raise AssertionError(f"{bad.dtype} {bad.shape} accepted")
    assert not (tmp_path / "bad.png").exists()


def test_writing_a_preview_imports_no_plotting(tmp_path):
    code = ("import sys, numpy as np; from pipeline.images import write_render; "
            f"write_render({str(tmp_path / 'r.exr')!r}, np.full((4, 6, 3), 0.5, np.float32)); "
            "heavy = sorted(m for m in ('colour', 'matplotlib') if m in sys.modules); "
            "print(heavy); sys.exit(1 if heavy else 0)")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "r.png").stat().st_size > 0
