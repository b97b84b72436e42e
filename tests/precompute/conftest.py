"""Fixtures of the precompute tests: a tiny two-exemplar tiling (plain and 4/1 satin, a few fibres per
ply, flat surface), built once per session through the CLI like any user's tiling."""
import pytest

TINY = """
seed = 3
[yarn]
fibers_per_ply = {fibers}
[weave]
spacing = [0.1, 0.1]
[[exemplars]]
name = "plain"
pattern = "plain"
[[exemplars]]
name = "satin"
pattern = "satin"
n = 5
[tiling]
repeat = [1, 1]
block_map = [[0, 1], [1, 0]]
[surface]
kind = "flat"
resolution = [2, 2]
"""


def make_tiling(directory, fibers=2):
    """Tile the tiny configuration into ``directory / tiling.zarr`` (returns the path)."""
    from pipeline.cli import main

    cfg = directory / "tiny.toml"
    cfg.write_text(TINY.format(fibers=fibers))
    out = directory / "tiling.zarr"
    assert main(["tile", str(cfg), "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="session")
def tiny_tiling(tmp_path_factory):
    """(path, ShellScene, Artifact) of the tiny tiling."""
    from pipeline.runners.tile import load_tiling

    path = make_tiling(tmp_path_factory.mktemp("tiny_tiling"))
    sc, art = load_tiling(path)
    return path, sc, art
