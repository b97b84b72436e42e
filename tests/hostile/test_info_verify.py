"""``loomlight info --verify`` (issue 58, item 7): ``info`` reads metadata only, so an artifact with a deleted
or garbled chunk shows as usual (exit 0) -- and says that it read no array; ``--verify`` reads every array
against the sha256 and crc32c recorded at write and refuses such an artifact as bad input
(``tests/hostile/contract.py``: exit code 2, one line naming the artifact and the array, nothing changed).
Reference: the checksums recorded at write; the intact artifact verifies."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.hostile.contract import assert_refused

H = Path(__file__).resolve().parent


def _chunk(artifact: Path, array: str) -> Path:
    return sorted(p for p in (artifact / array).rglob("*") if p.is_file() and p.name != "zarr.json")[0]


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("info_verify")
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "-o", str(W / "yarns.zarr")]) == 0
    for name in ("deleted.zarr", "garbled.zarr"):
        shutil.copytree(W / "yarns.zarr", W / name)
    _chunk(W / "deleted.zarr", "points").unlink()
    chunk = _chunk(W / "garbled.zarr", "points")
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0x5A
    chunk.write_bytes(bytes(data))
    return W


def test_info_says_it_read_no_array(cli, ws):
    code, out, err = cli("info", ws / "deleted.zarr")
    assert code == 0, err
    assert "info --verify" in " ".join(out.split())
    code, out, err = cli("info", ws / "deleted.zarr", "--json")
    assert code == 0 and json.loads(out)["arrays_verified"] is False


@pytest.mark.parametrize("name", ["deleted.zarr", "garbled.zarr"])
def test_verify_refuses_a_damaged_chunk(cli, ws, name):
    assert_refused(cli, ws, ["info", ws / name, "--verify"], f"{name}: array points")


def test_verify_passes_an_intact_artifact(cli, ws):
    code, out, err = cli("info", ws / "yarns.zarr", "--verify", "--json")
    assert code == 0, err
    assert json.loads(out)["arrays_verified"] is True
    code, out, err = cli("info", ws / "yarns.zarr", "--verify")
    assert code == 0 and "every array read" in " ".join(out.split())
