"""Checks shared by the inspector tests: a picture is a PNG of sensible size, not blank, without wide
empty margins, and its text is legible (no font below ``pipeline.inspectors.MIN_FONT_PT``)."""
from __future__ import annotations

import contextlib

import numpy as np


def read_png(path) -> np.ndarray:
    """(H, W, 3) floats in [0, 1]."""
    import matplotlib.image as mpimg

    return np.asarray(mpimg.imread(str(path)), float)[..., :3]


def blank_runs(img: np.ndarray, background=(1.0, 1.0, 1.0), tol=2 / 255):
    """(rows, cols): boolean masks of the rows and columns made only of the background colour."""
    bg = np.all(np.abs(img - np.asarray(background)) <= tol, axis=-1)
    return bg.all(axis=1), bg.all(axis=0)


def edge_run(mask: np.ndarray) -> int:
    """The longer of the runs of True at the two ends of ``mask``."""
    def run(m):
        n = np.argmin(m) if not m.all() else len(m)
        return int(n)
    return max(run(mask), run(mask[::-1]))


def longest_run(mask: np.ndarray) -> int:
    best = cur = 0
    for v in mask:
        cur = cur + 1 if v else 0
        best = max(best, cur)
    return best


def assert_legible_png(path, min_size=(200, 150), max_size=(4000, 4000)):
    """The PNG exists, has a sensible size and is not blank (many distinct colours, not one flat field)."""
    img = read_png(path)
    h, w = img.shape[:2]
    assert min_size[0] <= w <= max_size[0] and min_size[1] <= h <= max_size[1], f"{path}: {w}x{h} pixels"
    assert img.std() > 0.05, f"{path}: nearly uniform"
    nonwhite = np.any(img < 0.95, axis=-1).mean()
    assert nonwhite > 0.05, f"{path}: {100 * nonwhite:.1f}% of the pixels drawn"
    return img


@contextlib.contextmanager
def saved_figures(monkeypatch):
    """Record every matplotlib figure saved inside the block (list of figures, read after savefig)."""
    from matplotlib.figure import Figure

    figs = []
    orig = Figure.savefig

    def savefig(self, *a, **k):
        figs.append(self)
        return orig(self, *a, **k)

    monkeypatch.setattr(Figure, "savefig", savefig)
    yield figs


def small_texts(fig, min_pt):
    """[(text, size)] of the visible, non-empty texts below ``min_pt`` points."""
    from matplotlib.text import Text

    out = []
    for t in fig.findobj(Text):
        if t.get_visible() and t.get_text().strip() and t.get_fontsize() < min_pt - 1e-9:
            out.append((t.get_text(), t.get_fontsize()))
    return out
