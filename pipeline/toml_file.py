"""TOML files: one reader with one error path, and a writer for plain data.

``read_toml(path, what="file")`` returns the document as a dict. Every way a file can fail to be
TOML is one ``LoomError`` line naming the file (exit code 2): ``<what> not found``,
``is a directory, not a <what>``, ``byte N: not a UTF-8 text file``,
``line N: not valid TOML: ...``, and ``<key>: nan is not a finite number``: TOML allows nan and inf
but no loomlight file takes them, so they are refused wherever they appear (``lights[0].irradiance``).
Callers check the document itself (``pipeline.schemas.validate``).

``dumps_toml(doc)`` writes a document of plain data (tables, arrays, strings, numbers, booleans)
as top-level ``key = value`` lines, tables inline; ``tomllib.loads`` reads it back unchanged
(the sweep's derived scene files); ``toml_value(v, bare_keys)`` writes one value (bare keys: the room's
scene file, pipeline/room.py).
"""
from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

from .errors import LoomError


def read_toml(path, what: str = "file") -> dict:
    """The TOML document at ``path``; ``what`` names the file in the not-found and directory errors."""
    path = Path(path)
    if not path.exists():
        raise LoomError(path, None, f"{what} not found")
    if path.is_dir():
        raise LoomError(path, None, f"is a directory, not a {what}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise LoomError(path, f"byte {e.start}", "not a UTF-8 text file") from None
    except OSError as e:
        raise LoomError(path, None, f"cannot read the {what}: {e.strerror or e}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise LoomError(path, f"line {_line_of(e)}", f"not valid TOML: {e}") from None
    _refuse_non_finite(doc, path, "")
    return doc


def _refuse_non_finite(value, path, place: str) -> None:
    """A LoomError at the first nan or inf of a TOML document (place in the schemas' notation)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise LoomError(path, place or "<top>", f"{value} is not a finite number (loomlight takes no nan or inf)")
    if isinstance(value, dict):
        for k, v in value.items():
            _refuse_non_finite(v, path, f"{place}.{k}" if place else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _refuse_non_finite(v, path, f"{place}[{i}]")


def _line_of(e: tomllib.TOMLDecodeError):
    """The line of a TOML error (``lineno`` from Python 3.14, else parsed from the message)."""
    line = getattr(e, "lineno", None)
    if line is None:
        m = re.search(r"at line (\d+)", str(e))
        line = int(m.group(1)) if m else "?"
    return line


# ------------------------------------------------------------------------------------------------
# TOML output (the scene files we derive are plain data: tables, arrays, strings, numbers, booleans)
BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def toml_value(v, bare_keys: bool = False) -> str:
    """One value of plain data as TOML text: tables inline, keys quoted, or bare where TOML allows with
    ``bare_keys`` (the style of the bundled scene files)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x, bare_keys) for x in v) + "]"
    if isinstance(v, dict):
        def key(k):
            return str(k) if bare_keys and BARE_KEY.fullmatch(str(k)) else json.dumps(str(k))

        return "{ " + ", ".join(f"{key(k)} = {toml_value(x, bare_keys)}" for k, x in v.items()) + " }" if v else "{}"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(doc: dict) -> str:
    """A TOML document of top-level ``key = value`` lines (tables as inline tables)."""
    return "".join(f"{json.dumps(str(k))} = {toml_value(v)}\n" for k, v in doc.items())
