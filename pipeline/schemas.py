"""JSON Schemas for every artifact kind and for scene files (``schemas/``), checked on write and read."""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import jsonschema

from .errors import LoomError

SCHEMA_DIR = Path(__file__).resolve().parents[1] / "schemas"


@lru_cache(maxsize=None)
def load_schema(name: str) -> dict:
    path = SCHEMA_DIR / f"{name}.schema.json"
    if not path.exists():
        raise LoomError(path, None, f"no schema named {name!r} in {SCHEMA_DIR}")
    schema = json.loads(path.read_text())
    if name == "scene":  # the [render] table is declared by the renderer registry
        from .renderers import render_schema

        schema["properties"]["render"] = render_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return schema


def json_path(error: jsonschema.ValidationError) -> str:
    parts = []
    for p in error.absolute_path:
        parts.append(f"[{p}]" if isinstance(p, int) else (f".{p}" if parts else str(p)))
    return "".join(parts) or "<top>"


def describe(error: jsonschema.ValidationError) -> tuple[str, str]:
    """(place, message) for the most specific error, phrased for a person."""
    best = jsonschema.exceptions.best_match([error]) or error
    place = json_path(best)
    if best.validator == "additionalProperties":
        allowed = sorted(best.schema.get("properties", {}))
        extra = sorted(set(best.instance) - set(allowed)) if isinstance(best.instance, dict) else []
        key = extra[0] if extra else "?"
        place = f"{place}.{key}" if place != "<top>" else key
        return place, f"unknown key {key!r} (allowed: {', '.join(allowed)})"
    return place, best.message


def validate(instance, name: str, file: str | Path | None, prefix: str = "") -> None:
    """Validate ``instance`` against ``schemas/<name>.schema.json`` or raise a one-line LoomError."""
    validator = jsonschema.Draft202012Validator(load_schema(name))
    errors = sorted(validator.iter_errors(instance), key=lambda e: (len(list(e.absolute_path)), str(e.absolute_path)))
    if errors:
        place, msg = describe(errors[0])
        raise LoomError(file, f"{prefix}{place}", msg)
