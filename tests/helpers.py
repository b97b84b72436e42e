"""Paths and reference data every test may need. ../shared is reference material: tests that use it
skip (``shared_file``) when it is absent."""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
DATA = ROOT / "data"

# the gentle swatch (exact lookups): scene text of the lookups' exactness and frame-sample tests
EXACTNESS_SWATCH = (DATA / "scenes" / "gentle_swatch.toml").read_text()


def shared_file(rel: str) -> Path:
    p = SHARED / rel
    if not p.exists():
        pytest.skip(f"reference file ../shared/{rel} is not present (../shared is reference material, absent on this machine)")
    return p
