"""Curve file formats (pipeline/io): BCC, OBJ polylines, plain-text polylines.

References: read-write-read round trips must be bitwise identical in float32 (closed flags
included); every malformed input raises LoomError naming the file and the place; the real
openwork_trellis_pattern.bcc parses with the counts given in ../shared/reference/formats.md.
"""
import struct

import numpy as np
import pytest

from pipeline.curveset import CurveSet
from pipeline.errors import LoomError
from pipeline.io import bcc, obj, polyline_txt, read_curves, write_curves
from tests.helpers import DATA, shared_file


def _random_curves(seed=3, with_radius=False):
    rng = np.random.default_rng(seed)
    pts, closed = [], []
    for c, n in enumerate([2, 5, 17, 3]):
        # values that need all 24 mantissa bits, including tiny and large magnitudes
        p = (rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-6, 6, (n, 3))).astype(np.float32)
        pts.append(p)
        closed.append(c % 2 == 1 and n >= 3)
    radii = [rng.uniform(0.01, 0.1, len(p)).astype(np.float32) for p in pts] if with_radius else None
    return CurveSet(points=pts, closed=closed, group=["other"] * len(pts), point_radius=radii)


def _assert_same(a: CurveSet, b: CurveSet):
    assert len(a.points) == len(b.points)
    assert a.closed == b.closed
    for p, q in zip(a.points, b.points):
        assert np.asarray(q).dtype == np.float32
        assert np.array_equal(np.asarray(p, np.float32).view(np.uint32), np.asarray(q).view(np.uint32))


# ---------------------------------------------------------------- round trips (bitwise float32)

@pytest.mark.parametrize("up_axis", [0, 1, 2])
@pytest.mark.parametrize("ctype", ["C0", "PL"])
def test_bcc_round_trip_bitwise(tmp_path, up_axis, ctype):
    cs = _random_curves()
    f = tmp_path / "a.bcc"
    bcc.write(f, cs, curve_type=ctype, up_axis=up_axis)
    back = bcc.read(f)
    _assert_same(cs, back)
    assert back.curve_type == ("catmull-rom" if ctype == "C0" else "polyline")
    assert back.notes["up_axis"] == up_axis
    # write-read again: the same bytes
    bcc.write(tmp_path / "b.bcc", back, up_axis=up_axis)
    assert (tmp_path / "b.bcc").read_bytes() == f.read_bytes()
    # size: header + per curve 4 + 12 n
    assert f.stat().st_size == 64 + sum(4 + 12 * len(p) for p in cs.points)


def test_bcc_up_axis_is_a_rotation_to_z_up():
    """Reference: the up axis of the file maps to +z and the permutation has determinant +1."""
    for u in range(3):
        e = np.eye(3, dtype=np.float32)
        m = bcc.to_z_up(e, u)  # row i = image of basis vector i
        assert np.array_equal(m[u], [0, 0, 1])
        assert np.isclose(np.linalg.det(m), 1.0)
        assert np.array_equal(bcc.from_z_up(bcc.to_z_up(e, u), u), e)
    # y-up file point (1, 2, 3): up = y = 2 -> z; x_new = file z, y_new = file x
    assert bcc.to_z_up(np.array([[1.0, 2.0, 3.0]]), 1).tolist() == [[3.0, 1.0, 2.0]]


def test_obj_round_trip_bitwise(tmp_path):
    cs = _random_curves(5)
    cs.group = ["warp", "warp", "weft", "other"]
    f = tmp_path / "a.obj"
    obj.write(f, cs)
    back = obj.read(f)
    _assert_same(cs, back)
    assert back.group == cs.group


def test_txt_round_trip_bitwise_with_radius(tmp_path):
    cs = _random_curves(7, with_radius=True)
    f = tmp_path / "a.txt"
    polyline_txt.write(f, cs)
    back = polyline_txt.read(f)
    _assert_same(cs, back)
    for r, q in zip(cs.point_radius, back.point_radius):
        assert np.array_equal(r.view(np.uint32), q.view(np.uint32))
    cs.point_radius = None
    polyline_txt.write(f, cs)
    assert polyline_txt.read(f).point_radius is None


def test_bundled_samples_parse(tmp_path):
    b = read_curves(DATA / "curves" / "ring_and_helix.bcc")
    assert b.closed == [True, False] and [len(p) for p in b.points] == [24, 40]
    o = read_curves(DATA / "curves" / "two_polylines.obj")
    assert o.closed == [True, False] and [len(p) for p in o.points] == [4, 5]
    assert o.group == ["warp", "weft"]
    assert np.array_equal(o.points[1][0], [0, 0, 0.5])  # l -5 ... resolved relative to 9 vertices
    t = read_curves(DATA / "curves" / "mitsuba_curves.txt")
    assert [len(p) for p in t.points] == [4, 3] and t.point_radius[1][0] == np.float32(0.015)
    # cross-format: BCC -> OBJ -> TXT -> BCC is still bitwise the same
    write_curves(tmp_path / "x.obj", b)
    write_curves(tmp_path / "x.txt", read_curves(tmp_path / "x.obj"))
    write_curves(tmp_path / "x.bcc", read_curves(tmp_path / "x.txt"))
    _assert_same(b, read_curves(tmp_path / "x.bcc"))
    # scale multiplies coordinates
    s = read_curves(DATA / "curves" / "ring_and_helix.bcc", scale=2.0)
    assert np.allclose(s.points[0], 2.0 * b.points[0])


def test_real_bcc_counts():
    """Reference: ../shared/reference/formats.md: C0, up axis 2, one open curve, 19,730 points."""
    path = shared_file("data/openwork_trellis_pattern.bcc")
    assert path.stat().st_size == 236_828
    cs = read_curves(path)
    assert len(cs.points) == 1 and cs.closed == [False]
    assert len(cs.points[0]) == 19_730
    assert cs.curve_type == "catmull-rom" and cs.notes["up_axis"] == 2
    assert np.isfinite(cs.points[0]).all()
    assert 236_828 == 64 + 4 + 12 * 19_730


# ---------------------------------------------------------------- bad BCC input

def _bcc_bytes(curves, sig=b"BCC", nbytes=0x44, ctype=b"C0", dims=3, up=2, ncurves=None, npoints=None, tail=b""):
    body = b""
    for n, pts in curves:
        body += struct.pack("<i", n) + np.asarray(pts, "<f4").tobytes()
    nc = len(curves) if ncurves is None else ncurves
    npt = sum(abs(n) for n, _ in curves) if npoints is None else npoints
    return struct.pack("<3sB2sbbQQ40s", sig, nbytes, ctype, dims, up, nc, npt, b"test") + body + tail


GOOD = [(3, np.arange(9.0).reshape(3, 3)), (-4, np.arange(12.0).reshape(4, 3)), (2, np.ones((2, 3)))]


def _nan_curves():
    bad = [list(c) for c in GOOD]
    p = np.array(bad[2][1], dtype=float)
    p[1, 2] = np.inf
    bad[2][1] = p
    return [tuple(c) for c in bad]


BAD_BCC = {
    "truncated header": (_bcc_bytes(GOOD)[:40], "byte 40", "truncated"),
    "wrong signature": (_bcc_bytes(GOOD, sig=b"BCD"), "byte 0", "signature"),
    "byte count": (_bcc_bytes(GOOD, nbytes=0x48), "byte 3", "byte count"),
    "curve type": (_bcc_bytes(GOOD, ctype=b"BZ"), "byte 4", "curve type"),
    "dims": (_bcc_bytes(GOOD, dims=2), "byte 6", "dimension"),
    "up axis": (_bcc_bytes(GOOD, up=3), "byte 7", "up axis"),
    "count overruns": (_bcc_bytes(GOOD[:2] + [(50, np.ones((2, 3)))], npoints=57), "byte 156: curve 2", "overruns"),
    "truncated curve": (_bcc_bytes(GOOD)[:-5], "curve 2", "overruns"),
    "too many curves in header": (_bcc_bytes(GOOD, ncurves=4), "curve 3", "declares 4"),
    "point count disagrees": (_bcc_bytes(GOOD, npoints=10), "byte 16", "declares 10"),
    "trailing bytes": (_bcc_bytes(GOOD, tail=b"\0\0\0"), "byte 184", "3 trailing bytes"),
    "non-finite": (_bcc_bytes(_nan_curves()), "curve 2, point 1", "non-finite"),
    "one-point curve": (_bcc_bytes([(3, np.ones((3, 3))), (1, np.ones((1, 3)))]), "curve 1", "at least 2"),
    "zero-point curve": (_bcc_bytes([(0, np.ones((0, 3)))]), "curve 0", "at least 2"),
}


@pytest.mark.parametrize("case", sorted(BAD_BCC))
def test_bcc_bad_input_names_file_and_place(tmp_path, case):
    blob, place, words = BAD_BCC[case]
    f = tmp_path / "bad.bcc"
    f.write_bytes(blob)
    with pytest.raises(LoomError) as e:
        read_curves(f)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(str(f) + ": ")
    assert place in msg and words in msg, msg


def test_good_bcc_fixture_is_good(tmp_path):
    """The bad cases above differ from this valid file by one defect each."""
    f = tmp_path / "good.bcc"
    f.write_bytes(_bcc_bytes(GOOD))
    cs = read_curves(f)
    assert cs.closed == [False, True, False] and [len(p) for p in cs.points] == [3, 4, 2]


# ---------------------------------------------------------------- bad OBJ / text input

BAD_OBJ = {
    "missing vertex": ("v 0 0 0\nv 1 0 0\n# comment\nl 1 2 3\n", "line 4", "missing vertex 3"),
    "negative too far": ("v 0 0 0\nl -1 -2\nv 1 1 1\n", "line 2", "missing vertex -2"),
    "zero index": ("v 0 0 0\nv 1 0 0\nl 0 1\n", "line 3", "missing vertex 0"),
    "bad coordinate": ("v 0 zero 0\n", "line 1", "bad vertex coordinate"),
    "nan coordinate": ("v 0 nan 0\n", "line 1", "non-finite"),
    "bad index": ("v 0 0 0\nv 1 0 0\nl 1 two\n", "line 3", "bad vertex index"),
    "single point": ("v 0 0 0\nl 1\n", "line 2", "at least 2"),
}


@pytest.mark.parametrize("case", sorted(BAD_OBJ))
def test_obj_bad_input(tmp_path, case):
    text, place, words = BAD_OBJ[case]
    f = tmp_path / "bad.obj"
    f.write_text(text)
    with pytest.raises(LoomError) as e:
        read_curves(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}: {place}: ") and words in msg, msg


def test_obj_negative_indices_and_other_records(tmp_path):
    f = tmp_path / "a.obj"
    f.write_text("o thing\nv 0 0 0\nv 1 0 0\nvn 0 0 1\nl -2 -1\nv 2 0 0 1.0\nf 1 2 3\nl 1/1 2/2 3/3 1/1\n")
    cs = read_curves(f)
    assert cs.closed == [False, True]
    assert cs.points[0].tolist() == [[0, 0, 0], [1, 0, 0]]
    assert cs.points[1].tolist() == [[0, 0, 0], [1, 0, 0], [2, 0, 0]]


BAD_TXT = {
    "bad token": ("0 0 0\n1 x 0\n", "line 2", "bad number 'x'"),
    "mixed columns in a curve": ("0 0 0 0.1\n1 0 0\n", "line 2", "mixed 3/4"),
    "two columns": ("0 0\n", "line 1", "got 2 values"),
    "single point curve": ("0 0 0\n1 1 1\n\n2 2 2\n", "line 4", "at least 2"),
    "radius column disagrees between curves": ("0 0 0 1\n1 0 0 1\n\n0 1 0\n1 1 0\n", "line 4", "all or none"),
    "non-positive radius": ("0 0 0 0\n1 0 0 1\n", "line 1", "not positive"),
}


@pytest.mark.parametrize("case", sorted(BAD_TXT))
def test_txt_bad_input(tmp_path, case):
    text, place, words = BAD_TXT[case]
    f = tmp_path / "bad.txt"
    f.write_text(text)
    with pytest.raises(LoomError) as e:
        read_curves(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}: {place}: ") and words in msg, msg


def test_txt_comments_and_blank_runs(tmp_path):
    f = tmp_path / "a.txt"
    f.write_text("# header\n0 0 0\n# a comment inside a curve is not a break\n1 0 0  # trailing\n"
                 "\n\n\n0 1 0\n1 1 0\n2 1 0\n0 1 0\n")
    cs = read_curves(f)
    assert [len(p) for p in cs.points] == [2, 3]
    assert cs.closed == [False, True]  # first == last point -> closed, repeat dropped


def test_unknown_suffix_and_missing_file(tmp_path):
    f = tmp_path / "a.ply"
    f.write_text("ply\n")
    with pytest.raises(LoomError, match=r"a\.ply: unknown curve file type"):
        read_curves(f)
    with pytest.raises(LoomError, match="no such file"):
        read_curves(tmp_path / "none.bcc")
