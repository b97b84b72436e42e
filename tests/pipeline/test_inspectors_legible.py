"""``loomlight inspect`` pictures are legible: every artifact kind a stage writes has an inspector, no
text is below 9 pt at the saved resolution, the render inspector's picture is cut to its panels (no
background margin wider than 3% of the width), and the evaluation inspector draws an evaluation
artifact: reference and test images, error maps, the metrics table with the artifact's numbers.

The per-kind pictures of real artifacts (yarns, tables, fibers, tiling, svf, iirtf, render) are checked
with ``tests.inspector_checks.assert_legible_png`` where each stage's tests build their artifacts."""
import re
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import ROOT
from tests.inspector_checks import assert_legible_png, blank_runs, edge_run, longest_run, saved_figures, small_texts


def written_kinds():
    """Every kind an ``ArtifactWriter`` is created with in pipeline/."""
    kinds = set()
    for f in (ROOT / "pipeline").rglob("*.py"):
        for m in re.finditer(r"ArtifactWriter\([^)]*?kind=\"(\w+)\"", f.read_text(), re.S):
            kinds.add(m.group(1))
    return kinds


def test_every_artifact_kind_has_an_inspector():
    from pipeline.inspectors import inspector_for

    kinds = written_kinds()
    assert {"yarns", "tables", "fibers", "grid", "tiling", "svf", "iirtf", "render", "evaluation"} <= kinds
    for k in sorted(kinds):
        assert callable(inspector_for(k).inspect), k


class FakeArtifact:
    """The reading interface the inspectors use (arrays by name, summary, params, meta, path)."""

    def __init__(self, arrays, summary, params=None, meta=None, path="fake.zarr"):
        self.arrays, self.summary, self.params = arrays, summary, params or {}
        self.meta = meta or {}
        self.path = Path(path)

    def __getitem__(self, k):
        return self.arrays[k]

    def __contains__(self, k):
        return k in self.arrays


def fake_render(h=60, w=80, seed=0):
    rng = np.random.default_rng(seed)
    img = (0.1 + 0.8 * rng.random((h, w, 3))).astype(np.float32)
    yy, xx = np.mgrid[:h, :w]
    alpha = ((yy - h / 2) ** 2 + (xx - w / 2) ** 2 < (h / 3) ** 2).astype(np.float32)
    return FakeArtifact({"image": img, "channels/A": alpha, "channels/depth": 3 * alpha,
                         "channels/variance": 0.01 * rng.random((h, w)).astype(np.float32)},
                        {"method": "fiberpath", "width": w, "height": h, "spp": 4, "wall_time_s": 1.0,
                         "paths_per_s": 1e5, "rays_per_s": 3e5, "mean_rgb": img.reshape(-1, 3).mean(0).tolist()})


@pytest.mark.parametrize("size,shape", [((1200, 900), (60, 80)), ((1200, 300), (60, 80)), ((600, 900), (120, 40))])
def test_render_inspector_has_no_wide_margins(tmp_path, monkeypatch, size, shape):
    """The picture is cut to its panels: no all-background band wider than 3% of the width at an edge,
    none inside wider than 8% of the width; every text at least 9 pt."""
    from pipeline.inspectors import MIN_FONT_PT, render

    png = tmp_path / "r.png"
    with saved_figures(monkeypatch) as figs:
        render.inspect(fake_render(*shape), png, size=size)
    img = assert_legible_png(png, min_size=(150, 100))
    h, w = img.shape[:2]
    assert w <= size[0] + 20 and h <= size[1] + 20
    rows, cols = blank_runs(img)
    assert edge_run(cols) <= 0.03 * w and edge_run(rows) <= 0.03 * w, (edge_run(cols), edge_run(rows), w)
    assert longest_run(cols) <= 0.08 * w and longest_run(rows) <= 0.08 * w, (longest_run(cols), longest_run(rows))
    assert not small_texts(figs[0], MIN_FONT_PT)


def test_grid_inspector_titles_colour_bars_and_fonts(tmp_path, monkeypatch):
    """Four titled panels, a colour bar for each false-colour panel, no text below 9 pt."""
    from pipeline.inspectors import MIN_FONT_PT, grid

    rng = np.random.default_rng(1)
    den = rng.random((4, 5, 6)).astype(np.float32)
    d = rng.normal(size=(4, 5, 6, 3)).astype(np.float32)
    art = FakeArtifact({"density": den, "albedo": rng.random((4, 5, 6, 3)).astype(np.float32), "direction": d},
                       {"bounds": [[0, 0, 0], [1, 1, 1]], "resolution": [6, 5, 4], "occupied_fraction": 1.0,
                        "max_density": float(den.max())})
    png = tmp_path / "g.png"
    with saved_figures(monkeypatch) as figs:
        grid.inspect(art, png, size=(800, 600))
    assert_legible_png(png)
    fig = figs[0]
    titled = [a for a in fig.axes if a.get_title()]
    bars = [a for a in fig.axes if not a.get_title()]
    assert len(titled) == 4 and len(bars) == 3 and all(b.get_ylabel() for b in bars)
    assert not small_texts(fig, MIN_FONT_PT)


@pytest.fixture
def evaluation(tmp_path):
    """A tiny images-mode evaluation: a reference and two tests (one an offset, one a copy)."""
    from pipeline.images import write_render
    from pipeline.runners.evaluate import evaluate_images

    rng = np.random.default_rng(0)
    ref = (0.2 + 0.6 * rng.random((24, 32, 3))).astype(np.float32)
    write_render(tmp_path / "ref.exr", ref)
    write_render(tmp_path / "brighter.exr", ref + np.float32(0.125))
    write_render(tmp_path / "copy.exr", ref)
    ev = evaluate_images(tmp_path / "ref.exr", [tmp_path / "brighter.exr", tmp_path / "copy.exr"], tmp_path / "eval")
    return tmp_path, ev


def test_evaluation_inspector_images_errors_and_metrics(evaluation, cli, monkeypatch):
    """Reference and both tests as images, both error maps (log colour bar), the metrics table holding
    the evaluation's RMSE (0.125 for the offset: RMSE of a constant offset is the offset), fonts >= 9 pt."""
    from matplotlib.image import AxesImage
    from matplotlib.table import Table

    from pipeline.inspectors import MIN_FONT_PT
    from pipeline.report import fmt_num

    d, ev = evaluation
    png = d / "ev.png"
    with saved_figures(monkeypatch) as figs:
        code, _, err = cli("inspect", d / "eval" / "evaluation.zarr", "--png", png)
    assert code == 0, err
    assert_legible_png(png)
    fig = figs[0]
    titles = " | ".join(a.get_title() for a in fig.axes)
    for want in ("reference: ref.exr", "test: brighter.exr", "test: copy.exr", "relative squared error: brighter.exr",
                 "mean intensity per channel", "metrics against the reference"):
        assert want in titles, (want, titles)
    images = [im for a in fig.axes for im in a.get_children() if isinstance(im, AxesImage)]
    assert len(images) == 5                               # 3 images + 2 error maps
    cells = [c.get_text().get_text() for a in fig.axes for t in a.get_children() if isinstance(t, Table)
             for c in t.get_celld().values()]
    assert ev.metrics["brighter.exr"]["rmse"] == pytest.approx(0.125, rel=1e-6)
    assert fmt_num(ev.metrics["brighter.exr"]["rmse"]) in cells and "copy.exr" in cells
    assert any(a.get_ylabel().startswith("(t - r)^2") for a in fig.axes)   # the error maps' colour bar
    assert not small_texts(fig, MIN_FONT_PT)


def test_evaluation_inspector_says_when_an_image_is_gone(evaluation, cli, monkeypatch):
    d, _ = evaluation
    (d / "copy.exr").unlink()
    with saved_figures(monkeypatch) as figs:
        code, _, err = cli("inspect", d / "eval" / "evaluation.zarr", "--png", d / "ev.png")
    assert code == 0, err
    texts = [t.get_text() for a in figs[0].axes for t in a.texts]
    assert any("copy.exr not found" in t for t in texts), texts
