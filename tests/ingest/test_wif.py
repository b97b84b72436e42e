"""WIF drafts (pipeline/io/wif.py + stages/ingest/weave.py).

References: the plain-weave draft 54235plain.wif is a checkerboard; the interlacement of each
draft equals a brute-force evaluation of the WIF rule (warp end x over pick y iff a shaft of x
is lifted at y, inverted for a sinking shed); the bundled satin lift plan equals the closed-form
satin; units convert by their definitions; malformed drafts raise LoomError naming the section.
"""
import numpy as np
import pytest

from pipeline.errors import LoomError
from pipeline.generators import from_wif
from pipeline.io import read_curves, wif
from stages.ingest import weave
from tests.helpers import DATA, shared_file


def _real(name):
    """A real draft: bundled in data/drafts/ (2229.wif, 54235plain.wif), else from ../shared/data/."""
    p = DATA / "drafts" / name
    return p if p.exists() else shared_file(f"data/{name}")


def _brute(sections, rising=True):
    """Literal reading of the rule in formats.md from the raw sections (independent of parse())."""
    def table(name):
        out = {}
        for k, (v, _) in sections.get(name, {}).items():
            if k != "__line__":
                out[int(k)] = {int(t) for t in v.split(",") if t.strip()}
        return out
    th = table("threading")
    ends = int(sections["warp"]["threads"][0])
    picks = int(sections["weft"]["threads"][0])
    if "liftplan" in sections:
        lift = table("liftplan")
    else:
        tie, tr = table("tieup"), table("treadling")
        lift = {p: set().union(*[tie.get(t, set()) for t in ts]) for p, ts in tr.items()}
    over = np.zeros((ends, picks), bool)
    for x in range(1, ends + 1):
        for y in range(1, picks + 1):
            over[x - 1, y - 1] = bool(th.get(x, set()) & lift.get(y, set()))
    return over if rising else ~over


def test_plain_draft_is_checkerboard():
    path = _real("54235plain.wif")
    d = wif.parse(path)
    assert d.over.shape == (2, 2)
    assert d.over[0, 0] != d.over[0, 1] and d.over[0, 0] != d.over[1, 0] and d.over[0, 0] == d.over[1, 1]
    tiled = weave.tile(d.over, 4, 3)
    assert np.array_equal(tiled, weave.plain(8, 6)) or np.array_equal(tiled, ~weave.plain(8, 6))


@pytest.mark.parametrize("name,ends,picks,shafts", [("54235plain.wif", 2, 2, 2), ("3parallelwarps.wif", 3, 3, 3),
                                                    ("2229.wif", 24, 24, 3)])
def test_real_drafts_match_brute_force(name, ends, picks, shafts):
    path = _real(name)
    d = wif.parse(path)
    assert d.over.shape == (ends, picks) and d.shafts == shafts
    assert np.array_equal(d.over, _brute(wif.parse_sections(path)))
    # formats.md: Spacing 0.0185 cm, Thickness 0.0213 cm -> radius 0.01065 cm
    assert d.warp_spacing == pytest.approx(0.0185) and d.warp_radius == pytest.approx(0.0213 / 2)
    cs = read_curves(path)
    assert cs.group.count("warp") == ends and cs.group.count("weft") == picks


def test_2229_counts_and_colours():
    path = _real("2229.wif")
    d = wif.parse(path)
    assert d.treadles == 4
    # colour table 1 = (0,101,0) for all warp ends, 2 = white for all picks; sRGB decoded
    g = ((101 / 255 + 0.055) / 1.055) ** 2.4
    assert all(c == pytest.approx((0.0, g, 0.0)) for c in d.warp_colors)
    assert all(c == pytest.approx((1.0, 1.0, 1.0)) for c in d.weft_colors)


def test_3parallelwarps_missing_colour_entries_default():
    d = wif.parse(_real("3parallelwarps.wif"))
    # WARP COLORS lists ends 1-2 only and [WARP] has no Color: end 3 gets no colour (yarn type's)
    assert d.warp_colors[2] is None and d.warp_colors[0] is not None
    # all ends on shaft 1; treadles 1,2,1 lift shafts 1,2,1: over, under, over for every end
    assert d.over.tolist() == [[True, False, True]] * 3


def test_bundled_twill_draft():
    path = DATA / "drafts" / "twill_2x2.wif"
    d = wif.parse(path)
    assert np.array_equal(d.over, _brute(wif.parse_sections(path)))
    for row in d.over:
        assert weave.float_lengths(row, True) == [2, 2] and weave.float_lengths(row, False) == [2, 2]
    # Millimeters: spacing 1.0 mm = 0.1 cm, thickness 0.4 mm -> radius 0.02 cm
    assert d.warp_spacing == pytest.approx(0.1) and d.warp_radius == pytest.approx(0.02)
    # [WARP] Color=1 applies to every end (no WARP COLORS section)
    assert d.warp_colors[0] == d.warp_colors[7] and d.warp_colors[0][0] > d.warp_colors[0][1]


def test_bundled_satin_liftplan_and_odd_palette_range():
    path = DATA / "drafts" / "satin_5_liftplan.wif"
    d = wif.parse(path)
    assert d.notes["lift"] == "liftplan"
    assert np.array_equal(d.over, weave.satin(5, 10, 10, step=3))
    # Range 0..65535: 65535 -> 1.0, 52428 -> 0.8 (sRGB) -> linear
    lin = ((0.8 + 0.055) / 1.055) ** 2.4
    assert d.warp_colors[0] == pytest.approx((1.0, lin, 0.0), rel=1e-4)
    # weft picks 2, 4, ... have no WEFT COLORS entry and no [WEFT] Color: default None
    assert d.weft_colors[0] is not None and d.weft_colors[1] is None
    # Inches: 0.04 in = 0.1016 cm; keys and section names in mixed case were found
    assert d.warp_spacing == pytest.approx(0.1016) and d.warp_radius == pytest.approx(0.008 * 2.54)


def test_sinking_shed_inverts():
    path = DATA / "drafts" / "plain_sinking.wif"
    d = wif.parse(path)
    assert not d.rising
    assert np.array_equal(d.over, _brute(wif.parse_sections(path), rising=False))
    assert np.array_equal(d.over, ~_brute(wif.parse_sections(path), rising=True))
    # no Thickness: spacing-based radius
    assert d.warp_radius == pytest.approx(0.05 / 4)


def test_from_wif_repeat_and_max_threads():
    path = DATA / "drafts" / "twill_2x2.wif"
    cs = from_wif(path, repeat=[2, 3], max_threads=12, crimp=0.5)
    over = cs.notes["interlacement"]
    assert over.shape == (12, 12)
    assert np.array_equal(over, np.tile(wif.parse(path).over, (2, 3))[:12, :12])
    assert cs.group.count("warp") == 12 and cs.group.count("weft") == 12
    assert len(cs.color) == 24 and cs.color[0] is not None


def _draft(tmp_path, text):
    f = tmp_path / "d.wif"
    f.write_text(text)
    return f


BASE = "[WEAVING]\nShafts=2\nTreadles=2\n[WARP]\nThreads=2\n[WEFT]\nThreads=2\n"


@pytest.mark.parametrize("text,place,words", [
    ("[WEAVING]\nShafts=2\n[TIEUP]\n1=1\n", "[THREADING]", "missing"),
    (BASE + "[THREADING]\n1=1\n2=2\n", "[TREADLING]", "missing"),
    (BASE + "[THREADING]\n1=1\n2=2\n[TREADLING]\n1=1\n", "[TIEUP]", "missing"),
    (BASE + "[THREADING]\n1=1\n2=x\n[TIEUP]\n1=1\n[TREADLING]\n1=1\n", "[THREADING] line 10", "expected integers"),
    (BASE + "[THREADING]\n1=1\n2=3\n[TIEUP]\n1=1\n[TREADLING]\n1=1\n", "[WEAVING] line 2", "Shafts = 2, but shaft 3"),
    (BASE + "[THREADING]\n1=1\n5=1\n[TIEUP]\n1=1\n[TREADLING]\n1=1\n", "[WARP] line 5", "Threads = 2, but end 5"),
    (BASE.replace("[WARP]\n", "[WARP]\nUnits=furlongs\nSpacing=1\n")
     + "[THREADING]\n1=1\n[TIEUP]\n1=1\n[TREADLING]\n1=1\n",
     "[WARP] line 5", "Units = 'furlongs'"),
    (BASE + "Spacing=abc\n[THREADING]\n1=1\n[TIEUP]\n1=1\n[TREADLING]\n1=1\n", "[WEFT] line 8", "not a number"),
    (BASE + "[THREADING]\n1=1\n[TIEUP]\n1=1\n[TREADLING]\n1=1\n[WARP COLORS]\n1=4\n", "[WARP COLORS] line 15",
     "no entry"),
    ("[WEAVING]\nRising Shed=maybe\n[THREADING]\n1=1\n[LIFTPLAN]\n1=1\n", "[WEAVING] line 2", "expected yes or no"),
])
def test_bad_drafts(tmp_path, text, place, words):
    f = _draft(tmp_path, text)
    with pytest.raises(LoomError) as e:
        read_curves(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}: {place}"), msg
    assert words in msg, msg


def test_case_insensitive_sections_and_missing_counts(tmp_path):
    f = _draft(tmp_path, "[threading]\n1 = 1\n2 = 2\n3=\n[Tie Up]\n[tieup]\n1 = 1\n2=2\n[TreadLing]\n1=1\n2=2\n")
    d = wif.parse(f)
    # counts from the largest thread numbers; end 3 has an empty threading -> never lifted
    assert d.over.tolist() == [[True, False], [False, True], [False, False]]
    assert d.warp_spacing == pytest.approx(0.05)  # defaults: no Spacing, no Thickness
