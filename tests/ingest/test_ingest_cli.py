"""`loomlight ingest` end to end: the info contract, and every bad input of issue 2 item 8 gives exit code 2,
one line naming the file and the place, no artifact, and an existing artifact at the output path untouched.
Bad files are written here byte by byte (struct), independently of the project's writers."""
import json
import struct

import numpy as np
import pytest

from pipeline.artifacts import read_meta
from tests.helpers import ROOT


def bcc_bytes(curves, curve_type=b"C0", up=2, signature=b"BCC", count_override=None, total_override=None):
    body = b""
    total = 0
    for pts, closed in curves:
        n = len(pts)
        total += n
        body += struct.pack("<i", -n if closed else n) + np.asarray(pts, "<f4").tobytes()
    header = signature + bytes([0x44]) + curve_type + bytes([3, up])
    header += struct.pack("<QQ", count_override if count_override is not None else len(curves),
                          total_override if total_override is not None else total)
    header += b"test".ljust(40, b"\0")
    return header + body


GOOD = [(np.array([[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 1]], float), False),
        (np.array([[0, 2, 0], [1, 3, 0], [0, 4, 0]], float), True)]


@pytest.fixture
def existing(tmp_path, cli):
    """A good artifact already at the output path."""
    src = tmp_path / "good.bcc"
    src.write_bytes(bcc_bytes(GOOD))
    out = tmp_path / "yarns.zarr"
    code, _, err = cli("ingest", src, "-o", out, "--radius", "0.1")
    assert code == 0, err
    return out, read_meta(out)["content_hash"]


def test_info_json_contract(existing, cli):
    out, _ = existing
    code, text, _ = cli("info", out, "--json")
    doc = json.loads(text)
    assert code == 0
    assert doc["kind"] == "yarns" and doc["curves"] == 2 and doc["closed_curves"] == 1
    assert doc["control_points"] == 7
    assert np.allclose(doc["bounds"], [[0, 0, 0], [3, 4, 1]])


def test_rerun_with_same_inputs_is_skipped(existing, cli, tmp_path):
    out, h = existing
    meta0 = read_meta(out)
    code, _, err = cli("ingest", tmp_path / "good.bcc", "-o", out, "--radius", "0.1")
    assert code == 0 and "up to date" in err
    assert read_meta(out)["created"] == meta0["created"]
    code, _, err = cli("ingest", tmp_path / "good.bcc", "-o", out, "--radius", "0.2")
    assert code == 0 and read_meta(out)["build_key"] != meta0["build_key"]


def _bad_cases():
    nan = [(np.array([[0, 0, 0], [1, np.nan, 0], [2, 0, 0]], float), False)]
    short = [(np.array([[0, 0, 0]], float), False)] + GOOD
    good = bcc_bytes(GOOD)
    return {
        "truncated.bcc": (good[:-7], "byte"),
        "signature.bcc": (bcc_bytes(GOOD, signature=b"XYZ"), "signature"),
        "overrun.bcc": (bcc_bytes(GOOD)[:64] + struct.pack("<i", 900) + good[68:], "curve 0"),
        "nan.bcc": (bcc_bytes(nan), "curve 0, point 1"),
        "short.bcc": (bcc_bytes(short), "curve 0"),
        "nothreading.wif": (b"[WIF]\nVersion=1.1\n[CONTENTS]\nWEAVING=yes\nWARP=yes\nWEFT=yes\nTIEUP=yes\n"
                            b"TREADLING=yes\n"
                            b"[WEAVING]\nShafts=2\nTreadles=2\nRising Shed=yes\n[WARP]\nThreads=2\n[WEFT]\nThreads=2\n"
                            b"[TIEUP]\n1=1\n2=2\n[TREADLING]\n1=1\n2=2\n", "THREADING"),
        "missing.obj": (b"v 0 0 0\nv 1 0 0\nl 1 2 5\n", "line 3"),
        "scene.toml": (b"[fabric]\nsource = 'generator'\n[fabric.generator]\nkind = 'woven'\npattern = 'plain'\n"
                       b"[camera]\norigin = [0, 0, 1]\ntarget = [0, 0, 0]\nfvo = 30\n", "camera.fvo"),
    }


@pytest.mark.parametrize("name", list(_bad_cases()))
def test_bad_input_exit_2_one_line_artifact_untouched(name, tmp_path, cli, existing):
    out, before = existing
    content, place = _bad_cases()[name]
    bad = tmp_path / name
    bad.write_bytes(content)
    code, _, err = cli("ingest", bad, "-o", out, "--radius", "0.1")
    assert code == 2, err
    line = err.strip()
    assert len(line.splitlines()) == 1 and name in line and place in line, line
    assert read_meta(out)["content_hash"] == before
    fresh = tmp_path / "fresh.zarr"
    code, _, _ = cli("ingest", bad, "-o", fresh, "--radius", "0.1")
    assert code == 2 and not fresh.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_repeated_points_merged_with_warning_or_refused(tmp_path, cli):
    rep = [(np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 0, 0]], float), False)]
    src = tmp_path / "rep.bcc"
    src.write_bytes(bcc_bytes(rep))
    code, _, err = cli("ingest", src, "-o", tmp_path / "m.zarr", "--radius", "0.1")
    assert code == 0 and "merged 1 repeated" in err
    code, text, _ = cli("info", tmp_path / "m.zarr", "--json")
    assert json.loads(text)["control_points"] == 3
    code, _, err = cli("ingest", src, "-o", tmp_path / "r.zarr", "--radius", "0.1", "--refuse-duplicates")
    assert code == 2 and "curve 0, point 2" in err and not (tmp_path / "r.zarr").exists()


def test_forced_rebuild_is_byte_identical(existing, cli, tmp_path):
    """Determinism: the same input and parameters give the same content hash."""
    out, before = existing
    code, _, err = cli("ingest", tmp_path / "good.bcc", "-o", out, "--radius", "0.1", "--force")
    assert code == 0, err
    assert read_meta(out)["content_hash"] == before


def test_demo_scene_ingests_woven_swatch(tmp_path, cli):

    scene = ROOT / "data" / "scenes" / "demo.toml"
    out = tmp_path / "demo.zarr"
    code, _, err = cli("ingest", scene, "-o", out)
    assert code == 0, err
    code, text, _ = cli("info", out, "--json")
    doc = json.loads(text)
    assert doc["curves"] == 16 and doc["groups"] == ["warp", "weft"] and doc["closed_curves"] == 0
    assert [t["preset"] for t in doc["yarn_types"][:2]] == ["cotton1", "cotton1"]


def test_inspect_draws_yarn_tubes(existing, cli, tmp_path, offscreen_gl):
    """`inspect yarns.zarr --png` writes a non-blank picture within the requested size, cut to its
    content (with frame glyphs)."""
    from tests.inspector_checks import assert_legible_png

    out, _ = existing
    png = tmp_path / "yarns.png"
    code, _, err = cli("inspect", out, "--png", png, "--frames", "--width", "320", "--height", "200")
    assert code == 0, err
    assert_legible_png(png, min_size=(120, 60), max_size=(340, 220))
    code, _, err = cli("inspect", out)
    assert code == 2 and "--png" in err
