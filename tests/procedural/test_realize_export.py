"""Full realization (seed 000 §3.2, Eq. 7) and its exports.

References: the fibers artifact contract (docs/architecture.md), the model's extent bound (every
vertex within the yarn's bound of its axis, closed form from the parameters), the budget refusal
(exit 2, estimated size, no artifact), round trips of the Mitsuba text and BCC exports, and
byte-identical rebuilds.
"""
import numpy as np
import pytest

from pipeline.artifacts import Artifact
from pipeline.io import bcc
from pipeline.runners.tables import build
from stages.core.curves.closest import closest_point_on_curve

SCENE = """
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 1
picks = 2
spacing = 0.2
yarn_radius = 0.025
crimp = 0.5
samples_per_cell = 6
[yarns.default]
preset = "polyester1"
"""


@pytest.fixture(scope="module")
def realized(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("realize")
    (d / "s.toml").write_text(SCENE)
    assert main(["ingest", str(d / "s.toml"), "-o", str(d / "yarns.zarr")]) == 0
    assert main(["realize", str(d / "yarns.zarr"), "-o", str(d / "fibers.zarr"), "--spacing", "0.004"]) == 0
    return d


def test_fibers_artifact_contract(realized):
    fib = Artifact(realized / "fibers.zarr", kind="fibers")
    pts, rad, off = fib["points"], fib["point_radius"], fib["fiber_offsets"]
    F = len(off) - 1
    assert pts.dtype == np.float32 and pts.shape[1] == 3 and rad.dtype == np.float32 and len(rad) == len(pts)
    assert off[0] == 0 and off[-1] == len(pts) and np.all(np.diff(off) >= 2)
    for name, dt in (("fiber_yarn", np.int32), ("fiber_ply", np.int16), ("fiber_kind", np.int8)):
        assert fib[name].dtype == dt and len(fib[name]) == F
    assert set(np.unique(fib["fiber_kind"])) == {1, 2, 3}
    assert fib["yarn_albedo"].shape == (3, 3)
    # fibres are ordered yarn, ply, regular/loop before hair (the lookups' ranking)
    key = fib["fiber_yarn"].astype(np.int64) * 8 + fib["fiber_ply"] * 2 + (fib["fiber_kind"] == 3)
    assert np.all(np.diff(key) >= 0)
    s = fib.summary
    assert s["fibers"] == F and s["vertices"] == len(pts)
    assert s["bytes"]["total"] == s["bytes"]["regular"] + s["bytes"]["loop"] + s["bytes"]["hair"]


def test_vertices_lie_within_the_extent_bound(realized):
    """Every vertex lies within the model's extent bound of its yarn's axis (and hairs reach beyond the core)."""
    fib = Artifact(realized / "fibers.zarr", kind="fibers")
    cv, tab, info, _, _ = build(realized / "yarns.zarr")
    pts = fib["points"].astype(np.float64)
    off = fib["fiber_offsets"]
    yarn = np.repeat(fib["fiber_yarn"], np.diff(off))
    kind = np.repeat(fib["fiber_kind"], np.diff(off))
    sel = np.random.default_rng(0).choice(len(pts), 3000, replace=False)
    dist = np.array([np.sqrt(closest_point_on_curve(cv, int(yarn[i]), pts[i])[1]) for i in sel])
    ext = tab.yarn_extent[yarn[sel]]
    assert np.all(dist <= ext)
    core = dist[kind[sel] == 1]
    assert core.max() < dist.max() or (kind[sel] == 3).sum() == 0


def test_budget_refusal_names_the_size_and_writes_nothing(realized, cli):
    d = realized
    code, out, err = cli("realize", d / "yarns.zarr", "-o", d / "small.zarr", "--budget", "0.01")
    assert code == 2
    assert "--budget" in err and "MiB" in err and "vertices" in err
    assert not (d / "small.zarr").exists()


@pytest.mark.parametrize("args,needle", [
    (["--spacing", "0"], "--spacing"), (["--preset", "jute"], "unknown preset"), (["--radius", "-1"], "--radius"),
])
def test_realize_bad_options(realized, cli, args, needle):
    code, out, err = cli("realize", realized / "yarns.zarr", "-o", realized / "x.zarr", *args)
    assert code == 2 and needle in err


def test_mitsuba_text_round_trip(realized, cli):
    d = realized
    code, out, err = cli("export", d / "fibers.zarr", "-o", d / "fibers.txt")
    assert code == 0, err
    fib = Artifact(d / "fibers.zarr", kind="fibers")
    blocks = [b for b in (d / "fibers.txt").read_text().split("\n\n") if b.strip()]
    off = fib["fiber_offsets"]
    assert len(blocks) == len(off) - 1
    for f in (0, len(blocks) // 2, len(blocks) - 1):
        rows = np.array([[float(v) for v in line.split()] for line in blocks[f].strip().splitlines()])
        np.testing.assert_array_equal(rows[:, :3].astype(np.float32), fib["points"][off[f]:off[f + 1]])
        np.testing.assert_array_equal(rows[:, 3].astype(np.float32), fib["point_radius"][off[f]:off[f + 1]])


def test_bcc_round_trip(realized, cli):
    d = realized
    code, out, err = cli("export", d / "fibers.zarr", "-o", d / "fibers.bcc")
    assert code == 0, err
    cs = bcc.read(d / "fibers.bcc")
    fib = Artifact(d / "fibers.zarr", kind="fibers")
    off = fib["fiber_offsets"]
    assert len(cs.points) == len(off) - 1 and cs.curve_type == "polyline"
    np.testing.assert_array_equal(np.concatenate(cs.points), fib["points"])


def test_realization_is_deterministic(realized, cli):
    d = realized
    code, out, err = cli("realize", d / "yarns.zarr", "-o", d / "again.zarr", "--spacing", "0.004")
    assert code == 0, err
    a = Artifact(d / "fibers.zarr").meta["content_hash"]
    b = Artifact(d / "again.zarr").meta["content_hash"]
    assert a == b


def test_fibers_inspector_png(realized, cli, tmp_path, offscreen_gl):
    """The realized fibres of a yarn stretch render to a non-blank PNG (skips without off-screen OpenGL)."""
    png = tmp_path / "fibers.png"
    code, _, err = cli("inspect", realized / "fibers.zarr", "--png", png, "--yarn", "1",
                       "--width", "400", "--height", "300")
    assert code == 0, err
    from tests.inspector_checks import assert_legible_png

    assert_legible_png(png, min_size=(150, 60), max_size=(420, 320))
    code, _, err = cli("inspect", realized / "fibers.zarr", "--png", png, "--yarn", "7")
    assert code == 2 and "--yarn" in err
