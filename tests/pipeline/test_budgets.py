"""Memory refused up front (issue 16, item 2): a stage whose input implies more memory than its budget
refuses before it allocates anything large, with the estimate in its one error line, instead of
being killed by the OOM killer or swapping for minutes.

Contract (``pipeline/memory.py``): exit code 2, one line ``error: FILE: loomlight STAGE needs an
estimated N of memory (largest parts), over the budget of B (where B comes from)``, and the stage's
work never started -- the function that would generate the curves or build the tables (the first
large allocation) is replaced by a sentinel that records any call, and the record must stay empty.
The inputs are tiny files that *claim* huge sizes (a WIF header, a generator's ends and picks, a
preset's counts), so nothing here allocates much.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import DATA, ROOT

H = ROOT / "tests" / "hostile"
PRESET = (H / "preset_beta_nan.toml").read_text().replace("beta = nan", "beta = 0.5")  # cotton1, valid
WIF = (DATA / "drafts" / "plain_sinking.wif").read_text()
DEMO = (DATA / "scenes" / "demo.toml").read_text()


def _preset(tmp_path: Path, name: str, key: str, value: str) -> Path:
    lines = [f"{key} = {value}" if ln.startswith(f"{key} =") else ln for ln in PRESET.splitlines()]
    (tmp_path / f"{name}.toml").write_text("\n".join(lines) + "\n")
    return tmp_path / name  # --preset takes the path without .toml, as a bundled name


@pytest.fixture(scope="module")
def yarns(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("budgets")
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "-o", str(d / "yarns.zarr")]) == 0
    return d / "yarns.zarr"


@pytest.fixture
def sentinels(monkeypatch):
    """Replace the first large allocation of ingest, tables and realize by a recorder."""
    import pipeline.runners.ingest as ingest
    import pipeline.runners.realize as realize
    import pipeline.runners.tables as tables

    calls = []

    def record(name):
        def fn(*args, **kwargs):
            calls.append(name)
            raise AssertionError(f"{name} ran: the stage started its work")
        return fn

    monkeypatch.setattr(ingest, "curves_from_input", record("ingest curves_from_input"))
    monkeypatch.setattr(tables, "build", record("tables build"))
    monkeypatch.setattr(realize, "build", record("realize build"))
    monkeypatch.delenv("LOOMLIGHT_MEMORY_BUDGET", raising=False)
    return calls


def _refused(cli, calls, args, names):
    code, out, err = cli(*args)
    lines = err.strip().splitlines()
    assert code == 2, (code, out, err)
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err + out, err
    for name in names:
        assert name in lines[0], (name, lines[0])
    assert calls == [], calls
    return lines[0]


def test_wif_claiming_a_billion_threads(cli, tmp_path, sentinels):
    """Threads=1e9 in a 40-line WIF: the default budget (a fraction of the memory available) refuses it
    from the header alone (1e9 x 1e9 draft cells cannot fit any machine)."""
    wif = tmp_path / "threads.wif"
    wif.write_text(WIF.replace("Threads=6", "Threads=1000000000"))
    line = _refused(cli, sentinels, ["ingest", wif, "-o", tmp_path / "y.zarr"],
                    ["threads.wif", "needs an estimated", "1,000,000,000 ends x 1,000,000,000 picks",
                     "% of the", "available"])
    assert "TiB" in line and not (tmp_path / "y.zarr").exists()


def test_wif_claiming_two_billion_shafts(cli, tmp_path, sentinels):
    wif = tmp_path / "shafts.wif"
    wif.write_text(WIF.replace("Shafts=2", "Shafts=2000000000"))
    _refused(cli, sentinels, ["ingest", wif, "-o", tmp_path / "y.zarr", "--budget", "4096"],
             ["shafts.wif", "draft matrices", "2,000,000,000 shafts", "over the budget of 4.0 GiB (--budget)"])


@pytest.mark.parametrize("picks, budget, size", [(100_000, None, "TiB"), (8, "100", "GiB")])
def test_generator_with_100000_ends(cli, tmp_path, sentinels, picks, budget, size):
    """A scene generator of 100,000 ends: 100,000 picks is refused by any default budget; 8 picks
    (2.3 GiB estimated; measured peak 2.0 GiB when built) by --budget 100."""
    scene = tmp_path / "ends.toml"
    scene.write_text(DEMO.replace("ends = 8", "ends = 100000").replace("picks = 8", f"picks = {picks}"))
    args = ["ingest", scene, "-o", tmp_path / "y.zarr"] + (["--budget", budget] if budget else [])
    line = _refused(cli, sentinels, args, ["ends.toml", f"woven 100,000 x {picks:,}", "generated curves"])
    assert size in line


def test_tables_with_1e8_bins(cli, tmp_path, yarns, sentinels):
    _refused(cli, sentinels, ["tables", yarns, "--bins", "100000000", "-o", tmp_path / "t.zarr"],
             ["yarns.zarr", "loomlight tables needs an estimated", "100000000 bins", "TiB"])


@pytest.mark.parametrize("stage", ["tables", "realize"])
@pytest.mark.parametrize("key, value, words", [
    ("ply_num", "1000000", ["1000000 plies"]),
    ("fiber_num", "1000000000", ["1000000000 fibres"]),
    ("flyaway_hair_density", "26000", ["hairs", "hybrid z extents"]),  # the most the proportions allow
])
def test_presets_claiming_huge_counts(cli, tmp_path, yarns, sentinels, stage, key, value, words):
    """A preset of 1e6 plies (a 5-minute hang before), 1e9 fibres per ply (OOM-killed at 23.7 GB
    before), the densest hairs the preset limits allow: refused by a 1 GiB budget, from the estimate."""
    preset = _preset(tmp_path, key, key, value)
    _refused(cli, sentinels, [stage, yarns, "--preset", preset, "--budget", "1024", "-o", tmp_path / "o.zarr"],
             ["yarns.zarr", f"loomlight {stage} needs an estimated", "over the budget of 1.0 GiB", *words])


@pytest.mark.parametrize("stage", ["tables", "realize"])
def test_preset_hair_density_1e12_refused_by_its_limit(cli, tmp_path, yarns, sentinels, stage):
    """Hair density 1e12 per unit length is beyond what a preset may state (1e3 per yarn radius):
    refused naming the key before any estimate or build."""
    preset = _preset(tmp_path, "hair", "flyaway_hair_density", "1e12")
    _refused(cli, sentinels, [stage, yarns, "--preset", preset, "-o", tmp_path / "o.zarr"],
             ["hair.toml", "flyaway_hair_density", "1e+12"])


def test_realize_budget_1_refused_before_the_work(cli, tmp_path, yarns, sentinels):
    """``realize --budget 1``: refused from the expected counts, before the tables or any fibre exist
    (before: after 246 s and 13.3 GB on the alien sweater)."""
    _refused(cli, sentinels, ["realize", yarns, "--budget", "1", "-o", tmp_path / "f.zarr"],
             ["yarns.zarr", "loomlight realize needs an estimated", "realized fibres", "over the budget of 1.0 MiB"])
    assert not (tmp_path / "f.zarr").exists()


def test_environment_budget(cli, tmp_path, yarns, sentinels, monkeypatch):
    """LOOMLIGHT_MEMORY_BUDGET (MiB) is the budget when --budget is not given; a bad value is one line."""
    monkeypatch.setenv("LOOMLIGHT_MEMORY_BUDGET", "1")
    _refused(cli, sentinels, ["tables", yarns, "-o", tmp_path / "t.zarr"], ["LOOMLIGHT_MEMORY_BUDGET", "1.0 MiB"])
    monkeypatch.setenv("LOOMLIGHT_MEMORY_BUDGET", "lots")
    _refused(cli, sentinels, ["tables", yarns, "-o", tmp_path / "t.zarr"], ["LOOMLIGHT_MEMORY_BUDGET", "'lots'"])
