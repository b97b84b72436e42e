"""WIF (Weaving Information File) drafts -> interlacement, colours and thread sizes.

WIF is INI-like: ``[SECTION]`` headers and ``key=value`` lines. Section and key names are
case-insensitive (inner whitespace collapsed), values may carry spaces, ``;`` starts a comment
line, and sections may be missing. What loomlight uses:

- ``[WEAVING]`` Shafts, Treadles, Rising Shed (yes/no/true/false/1/0; default yes). A rising
  shed lifts the shafts of the tie-up or lift plan (their warp ends go over the pick); a
  sinking shed lowers them (the interlacement is inverted).
- ``[WARP]`` / ``[WEFT]`` Threads, Units, Spacing, Thickness, Color.
- ``[THREADING]`` end = shaft[,shaft...] (required: its absence is "[THREADING]: missing").
- ``[LIFTPLAN]`` pick = shafts lifted; used when present, else ``[TIEUP]`` treadle = shafts with
  ``[TREADLING]`` pick = treadle[,treadle...].
- ``[COLOR PALETTE]`` Range = lo,hi (default 0,255), ``[COLOR TABLE]`` index = r,g,b,
  ``[WARP COLORS]`` / ``[WEFT COLORS]`` thread = colour index, falling back to ``[WARP]`` /
  ``[WEFT]`` Color (an index, or r,g,b in the palette range), else no colour (the yarn type's).
  WIF colours are display (sRGB-encoded) values: they are mapped to [0, 1] by the range and
  decoded with the sRGB transfer function to linear RGB. ``[COLOR PALETTE]`` Form, when given, must
  be RGB; a component outside the range, an entry that is not three numbers, a thread naming a
  colour the table lacks: LoomError naming the section, line and key (exit 2). Where the colours go
  from here: ``pipeline.thread_colors`` and docs/wif-colours.md.

Defaults for threads without entries: an end missing from the threading is on no shaft (never
lifted: under every pick in a rising shed); a pick missing from the treadling / lift plan lifts
nothing. Shaft or treadle 0 means "none". Thread counts come from Threads, else from the
largest thread number used.

Lengths: Spacing and Thickness are converted to centimetres (loomlight's scene unit for
drafts): Units = Centimeters (default when absent), Millimeters (/10), Inches (x 2.54),
Decipoints (1/720 inch); each must then lie between 1 micrometre and 1 m (``MIN_THREAD_CM``,
``MAX_THREAD_CM``), else LoomError naming the section, line and key. ``scale`` multiplies the result.
Spacing missing: Thickness, else 0.05 cm. The yarn radius is Thickness / 2; without Thickness,
spacing / 4 (a radius that keeps crimped crossings free of interpenetration, see woven.py).

Not a draft: a file that is not text (a NUL byte, or more than 1 % control or undecodable bytes) or
that has neither a ``[WIF]`` section nor any section of a draft is refused as "not a WIF draft"
before any section is looked for.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LoomError

_UNITS_CM = {"centimeters": 1.0, "centimetres": 1.0, "cm": 1.0, "millimeters": 0.1, "millimetres": 0.1,
             "mm": 0.1, "inches": 2.54, "inch": 2.54, "in": 2.54, "decipoints": 2.54 / 720.0}
# Sections of a draft (WIF 1.1): a file with none of them, and no [WIF] section either, is no WIF draft.
DRAFT_SECTIONS = frozenset({"contents", "weaving", "warp", "weft", "threading", "tieup", "treadling", "liftplan",
                            "color palette", "color table", "warp colors", "weft colors", "warp spacing",
                            "weft spacing", "warp thickness", "weft thickness", "text", "notes"})
# A thread's spacing and thickness, in centimetres after Units (before the fabric's scale): more than a
# micrometre (finer than any fibre) and less than a metre.
MIN_THREAD_CM = 1e-4
MAX_THREAD_CM = 100.0
_YES = {"yes": True, "true": True, "1": True, "on": True, "y": True,
        "no": False, "false": False, "0": False, "off": False, "n": False}


@dataclass
class WifDraft:
    over: np.ndarray                      # (ends, picks) bool, True = warp over weft
    rising: bool
    warp_spacing: float                   # cm
    weft_spacing: float
    warp_radius: float
    weft_radius: float
    warp_colors: list = field(default_factory=list)   # per end linear RGB or None
    weft_colors: list = field(default_factory=list)   # per pick
    shafts: int = 0
    treadles: int = 0
    notes: dict = field(default_factory=dict)


def _norm(name: str) -> str:
    return " ".join(name.strip().lower().split())


def _not_text(data: bytes) -> bool:
    """True for bytes no WIF writer makes: a NUL, or more than 1 % control characters or undecodable bytes
    (a WIF is INI text, UTF-8 or an 8-bit code page such as Windows-1252; those decode with a few
    replacements at most)."""
    if b"\x00" in data:
        return True
    text = data.decode("utf-8", errors="replace")
    bad = sum(1 for ch in text if ch == "\ufffd" or (ch < " " and ch not in "\t\r\n\f"))
    return bad > max(8, len(text) // 100)


def parse_sections(path) -> dict:
    """{section: {key: (value, line number)}} plus '__line__' (header line) per section.

    A file that is not text, or text with neither a ``[WIF]`` section nor any section a draft has
    (``DRAFT_SECTIONS``), is refused as not a WIF draft (before any section is looked for)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except IsADirectoryError:
        raise LoomError(path, None, "is a directory, not a WIF draft") from None
    except OSError as e:
        raise LoomError(path, None, f"cannot read: {e.strerror or e}") from None
    if _not_text(data):
        raise LoomError(path, None, "not a WIF draft: the file is not text (binary data); a WIF draft is an INI-like "
                                    "text file opening with a [WIF] section")
    text = data.decode("utf-8", errors="replace")
    sections: dict[str, dict] = {}
    cur = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(";"):
            continue
        m = re.fullmatch(r"\[([^\]]*)\]", line)
        if m:
            name = _norm(m.group(1))
            cur = sections.setdefault(name, {"__line__": (None, lineno)})
            continue
        if cur is None or "=" not in line:
            continue  # text outside sections or free-text lines (e.g. [NOTES]) carry no draft data
        key, value = line.split("=", 1)
        cur[_norm(key)] = (value.strip(), lineno)
    if "wif" not in sections and not DRAFT_SECTIONS & set(sections):
        found = ", ".join(f"[{n.upper()}]" for n in list(sections)[:3])
        raise LoomError(path, None, "not a WIF draft: it has no [WIF] section and none of a draft's sections "
                                    "([WEAVING], [WARP], [WEFT], [THREADING], ...)"
                                    + (f"; its sections are {found}" + (", ..." if len(sections) > 3 else "")
                                       if sections else "; it has no [SECTION] header at all"))
    return sections


class _Reader:
    def __init__(self, path, sections):
        self.path, self.s = path, sections

    def err(self, sec, lineno, msg):
        place = f"[{sec.upper()}]" + (f" line {lineno}" if lineno else "")
        return LoomError(self.path, place, msg)

    def get(self, sec, key, default=None):
        return self.s.get(sec, {}).get(key, (default, None))

    def number(self, sec, key, default=None, kind=float):
        v, ln = self.get(sec, key)
        if v is None or v == "":
            return default
        try:
            x = kind(v.replace(" ", "")) if kind is int else float(v)
        except ValueError:
            raise self.err(sec, ln, f"{key.title()} = {v!r} is not a number") from None
        if not np.isfinite(x):
            raise self.err(sec, ln, f"{key.title()} = {v!r} is not finite")
        return x

    def int_list(self, sec, key, value, lineno):
        if value.strip() == "":
            return []
        try:
            return [int(t) for t in re.split(r"[,\s]+", value.strip()) if t]
        except ValueError:
            raise self.err(sec, lineno, f"{key} = {value!r}: expected integers separated by commas") from None

    def table(self, sec):
        """{thread number: (list of ints, line)} for a numbered section."""
        out = {}
        for key, (value, ln) in self.s.get(sec, {}).items():
            if key == "__line__":
                continue
            try:
                k = int(key)
            except ValueError:
                raise self.err(sec, ln, f"key {key!r} is not a thread number") from None
            if k < 1:
                raise self.err(sec, ln, f"thread number {k} must be >= 1")
            out[k] = (self.int_list(sec, key, value, ln), ln)
        return out


def _thread_colors(r: _Reader, ends: int, picks: int):
    """(warp colours, weft colours): per end / pick a linear RGB tuple, or None (no colour in the draft).

    ``[COLOR PALETTE]`` Range = lo,hi maps a component v to (v - lo) / (hi - lo); the result is an
    sRGB-encoded display value, decoded to linear (``pipeline.thread_colors.srgb_to_linear``). Form,
    when given, must be RGB. A component outside the range, a table entry that is not three numbers, a
    thread naming an index the table lacks: LoomError naming the section, line and key."""
    from ..thread_colors import srgb_to_linear

    lo, hi = 0.0, 255.0
    v, ln = r.get("color palette", "range")
    if v:
        parts = [t for t in re.split(r"[,\s]+", v.strip()) if t]
        try:
            if len(parts) != 2:
                raise ValueError
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise r.err("color palette", ln, f"Range = {v!r}: expected lo,hi") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise r.err("color palette", ln, f"Range = {v!r}: expected finite lo,hi with hi > lo")
    v, ln = r.get("color palette", "form")
    if v and _norm(v) != "rgb":
        raise r.err("color palette", ln, f"Form = {v!r}: only RGB palettes are read")

    def rgb(sec, key, value, ln):
        """Linear RGB of an ``r,g,b`` value in the palette range."""
        parts = [t for t in re.split(r"[,\s]+", value.strip()) if t]
        try:
            nums = [float(t) for t in parts]
        except ValueError:
            nums = None
        if nums is None or len(nums) != 3:
            raise r.err(sec, ln, f"{key} = {value!r}: expected a colour r,g,b (three numbers)")
        for x in nums:
            if not (np.isfinite(x) and lo <= x <= hi):
                raise r.err(sec, ln, f"{key} = {value!r}: component {x:g} is outside the palette range "
                                     f"{lo:g}..{hi:g} ([COLOR PALETTE] Range)")
        a = (np.asarray(nums) - lo) / (hi - lo)
        return tuple(float(x) for x in srgb_to_linear(a))

    ctable = {}
    for key, (value, ln) in r.s.get("color table", {}).items():
        if key == "__line__":
            continue
        try:
            k = int(key)
        except ValueError:
            raise r.err("color table", ln, f"key {key!r} is not a colour index") from None
        ctable[k] = rgb("color table", key, value, ln)

    def thread_colors(sec_colors, sec_thread, n):
        dflt = None
        v, ln = r.get(sec_thread, "color")
        if v:
            parts = [t for t in re.split(r"[,\s]+", v.strip()) if t]
            if len(parts) == 1:
                try:
                    k = int(parts[0])
                except ValueError:
                    raise r.err(sec_thread, ln, f"Color = {v!r}: expected a [COLOR TABLE] index or r,g,b") from None
                if k not in ctable:
                    raise r.err(sec_thread, ln, f"Color = {v!r}: colour {k} has no entry in [COLOR TABLE]")
                dflt = ctable[k]
            else:
                dflt = rgb(sec_thread, "Color", v, ln)
        out = [dflt] * n
        for k, (vals, ln) in r.table(sec_colors).items():
            if k > n:
                raise r.err(sec_colors, ln, f"thread {k} is beyond the {n} declared")
            if len(vals) != 1:
                raise r.err(sec_colors, ln, f"{k} = {','.join(map(str, vals))}: expected one [COLOR TABLE] index")
            if vals[0] not in ctable:
                raise r.err(sec_colors, ln, f"{k} = {vals[0]}: colour {vals[0]} has no entry in [COLOR TABLE]")
            out[k - 1] = ctable[vals[0]]
        return out

    return thread_colors("warp colors", "warp", ends), thread_colors("weft colors", "weft", picks)


def parse(path, scale: float = 1.0) -> WifDraft:
    path = Path(path)
    r = _Reader(path, parse_sections(path))
    s = r.s
    if "threading" not in s:
        raise LoomError(path, "[THREADING]", "missing: the draft has no threading section")

    v, ln = r.get("weaving", "rising shed", "yes")
    if v.strip().lower() not in _YES:
        raise r.err("weaving", ln, f"Rising Shed = {v!r}: expected yes or no")
    rising = _YES[v.strip().lower()]

    threading = r.table("threading")
    use_lift = "liftplan" in s
    lifts = r.table("liftplan") if use_lift else None
    if not use_lift:
        if "treadling" not in s:
            raise LoomError(path, "[TREADLING]", "missing: the draft has neither a treadling nor a [LIFTPLAN]")
        if "tieup" not in s:
            raise LoomError(path, "[TIEUP]", "missing: a treadling needs a tie-up")
        treadling = r.table("treadling")
        tieup = r.table("tieup")

    def count(sec, key, used, what):
        n = r.number(sec, key, None, int)
        top = max(used) if used else 0
        if n is None:
            return top
        if n < 0:
            raise r.err(sec, r.get(sec, key)[1], f"{key.title()} = {n} is negative")
        if top > n:
            raise r.err(sec, r.get(sec, key)[1], f"{key.title()} = {n}, but {what} {top} is used")
        return n

    ends = count("warp", "threads", list(threading), "end")
    pick_table = lifts if use_lift else treadling
    picks = count("weft", "threads", list(pick_table), "pick")
    if ends < 1 or picks < 1:
        raise LoomError(path, "[WARP]" if ends < 1 else "[WEFT]", "the draft has no threads")
    shafts_used = [x for vals, _ in threading.values() for x in vals]
    if use_lift:
        shafts_used += [x for vals, _ in lifts.values() for x in vals]
    else:
        shafts_used += [x for vals, _ in tieup.values() for x in vals]
    shafts = count("weaving", "shafts", shafts_used, "shaft")

    def matrix(table, n_rows, n_cols, sec, what):
        m = np.zeros((n_rows, max(n_cols, 1)), dtype=bool)
        for k, (vals, ln) in table.items():
            if k > n_rows:
                raise r.err(sec, ln, f"thread {k} is beyond the {n_rows} declared")
            for x in vals:
                if x < 0 or x > n_cols:
                    raise r.err(sec, ln, f"{what} {x} is outside 1..{n_cols}")
                if x:
                    m[k - 1, x - 1] = True
        return m

    from stages.ingest.weave import interlacement_from_draft

    th = matrix(threading, ends, shafts, "threading", "shaft")
    if use_lift:
        over = interlacement_from_draft(th, liftplan=matrix(lifts, picks, shafts, "liftplan", "shaft"), rising=rising)
        treadles = 0
    else:
        used = list(tieup) + [x for vals, _ in treadling.values() for x in vals]
        treadles = count("weaving", "treadles", used, "treadle")
        tu = matrix(tieup, treadles, shafts, "tieup", "shaft")
        tr = matrix(treadling, picks, treadles, "treadling", "treadle")
        over = interlacement_from_draft(th, tieup=tu, treadling=tr, rising=rising)

    warp_colors, weft_colors = _thread_colors(r, ends, picks)

    def sizes(sec):
        v, ln = r.get(sec, "units", "centimeters")
        unit = _UNITS_CM.get(_norm(v))
        if unit is None:
            raise r.err(sec, ln, f"Units = {v!r}: expected Centimeters, Millimeters, Inches or Decipoints")
        spacing = r.number(sec, "spacing")
        thick = r.number(sec, "thickness")
        for name, x in (("Spacing", spacing), ("Thickness", thick)):
            if x is None:
                continue
            text, ln = r.get(sec, name.lower())
            if x <= 0:
                raise r.err(sec, ln, f"{name} = {text} must be positive")
            cm = x * unit
            if not MIN_THREAD_CM < cm < MAX_THREAD_CM:
                raise r.err(sec, ln, f"{name} = {text} ({_norm(v).title()}) is {cm:.4g} cm: a thread's "
                                     f"{name.lower()} must lie between 1 micrometre and 1 m ({MIN_THREAD_CM:g} .. "
                                     f"{MAX_THREAD_CM:g} cm; WIF lengths are read in [{sec.upper()}] Units, "
                                     "Centimeters when absent)")
        spacing = spacing * unit if spacing is not None else (thick * unit if thick is not None else 0.05)
        radius = thick * unit / 2.0 if thick is not None else spacing / 4.0
        return spacing * scale, radius * scale

    warp_spacing, warp_radius = sizes("warp")
    weft_spacing, weft_radius = sizes("weft")
    return WifDraft(over=over, rising=rising, warp_spacing=warp_spacing, weft_spacing=weft_spacing,
                    warp_radius=warp_radius, weft_radius=weft_radius, warp_colors=warp_colors,
                    weft_colors=weft_colors, shafts=shafts, treadles=treadles,
                    notes={"lift": "liftplan" if use_lift else "tieup+treadling"})

