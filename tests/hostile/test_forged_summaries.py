"""Forged summaries (issue 58, cases 2, 3 and 9; item 2): summaries are checked against arrays when an
artifact is opened (``pipeline/artifact_checks.py``), and the parameters join the content hash. Each
refusal follows the contract of ``tests/hostile/contract.py`` (exit code 2, one line naming the file and
the place, the workspace untouched).

A tiling whose summary claims 10 exemplars where its arrays hold 2, an SVF whose resolution and an IIRTF
whose SH order were edited -- each with its content hash recomputed, so only the comparison with the
arrays' shapes can tell. Reference: the arrays' shapes as the stage wrote them; the artifacts as
written pass. The workspace: ``tests/hostile/precomputed.py``.
"""
from __future__ import annotations

import json

import pytest

from tests.hostile.contract import assert_refused, forge
from tests.hostile.precomputed import SVF_ARGS, build


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """The workspace (``tests/hostile/precomputed.py``) and the forged copies beside it."""
    W = build(tmp_path_factory.mktemp("forged_summaries"))

    def summary(key, value):
        return lambda attrs: attrs["summary"].__setitem__(key, value)

    forge(W / "tiling.zarr", W / "forged_tiling.zarr", summary("exemplars", 10))
    forge(W / "svf.zarr", W / "forged_svf.zarr", summary("resolution", [16, 16]))
    forge(W / "iirtf.zarr", W / "forged_iirtf.zarr", summary("order", 6))
    forge(W / "iirtf.zarr", W / "forged_iirtf_both.zarr",
          lambda a: a["summary"].update(order=6, sh_coefficients=49))
    forge(W / "svf.zarr", W / "edited_params.zarr", lambda a: a["loomlight"]["params"].__setitem__("resolution", 16),
          rehash=False)

    def old_hash(attrs):  # the content hash as loomlight computed it before the parameters joined it
        from pipeline.artifacts import content_digest

        m = attrs["loomlight"]
        m["content_hash"] = content_digest(m["kind"], attrs["summary"], m["arrays"], None)

    forge(W / "svf.zarr", W / "old_hash.zarr", old_hash, rehash=False)
    return W


def _prt(W, svf="svf.zarr", iirtf="iirtf.zarr"):
    return ["render", W / "scene.toml", "--method", "prt", "--fibers", W / "tiling.zarr", "--set", f"svf={W / svf}",
            "--set", f"iirtf={W / iirtf}", "--spp", "1", "--threads", "2", "-o", W / "render.exr"]


def test_forged_tiling_exemplar_count(cli, ws):
    """Case 2: was an IndexError (exit 1) in precompute svf."""
    line = assert_refused(cli, ws, ["precompute", "svf", ws / "forged_tiling.zarr", "-o", ws / "svf.zarr", *SVF_ARGS],
                          "forged_tiling.zarr: summary.exemplars", "says 10", "array ex_fibers")
    assert "holds the fibre ranges of 2" in line


def test_forged_svf_resolution(cli, ws):
    """Case 3: was 'could not broadcast' (exit 1) in render --method prt."""
    assert_refused(cli, ws, _prt(ws, svf="forged_svf.zarr"), "forged_svf.zarr: summary.resolution",
                   "16 x 16 = 256 pixels", "ssdf_mean")


@pytest.mark.parametrize("name", ["forged_iirtf.zarr", "forged_iirtf_both.zarr"])
def test_forged_iirtf_order(cli, ws, name):
    """Case 9: was exit 0 with another picture; the order is compared with the arrays' SH coefficients
    whether or not the forger also edited sh_coefficients."""
    assert_refused(cli, ws, _prt(ws, iirtf=name), f"{name}: summary.order", "says 6", "bcsdf_sh")


def test_forged_summary_refused_by_every_reader(cli, ws):
    """The check sits where an artifact is opened, so info and inspect refuse the same artifacts."""
    for name, key in (("forged_tiling.zarr", "summary.exemplars"), ("forged_svf.zarr", "summary.resolution"),
                      ("forged_iirtf.zarr", "summary.order")):
        assert_refused(cli, ws, ["info", ws / name], f"{name}: {key}")
        assert_refused(cli, ws, ["inspect", ws / name, "--png", ws / "x.png"], f"{name}: {key}")


def test_genuine_artifacts_pass_the_checks(cli, ws):
    """Reference: the artifacts as the stages wrote them open (info exit 0), their summaries agreeing
    with their arrays (``pipeline.artifact_checks``)."""
    for name in ("tiling.zarr", "svf.zarr", "iirtf.zarr"):
        code, out, err = cli("info", ws / name, "--json")
        assert code == 0, err
        assert json.loads(out)["kind"] == name.split(".")[0]


def test_params_join_the_content_hash(cli, ws):
    """An edited parameter (hash not recomputed) is refused like an edited summary; an artifact whose hash
    was computed without the parameters (an older loomlight) is refused with that reason."""
    assert_refused(cli, ws, ["info", ws / "edited_params.zarr"], "edited_params.zarr",
                   "do not match the content hash")
    assert_refused(cli, ws, ["info", ws / "old_hash.zarr"], "old_hash.zarr", "did not cover the parameters",
                   "rebuild it")
