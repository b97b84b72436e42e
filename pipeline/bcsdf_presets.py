"""BCSDF presets: ``data/bcsdf/<name>.toml`` files (or a TOML file by path) of the Khungurn et al. 2015 fibre
scattering parameters (``c_r``, ``c_tt``, ``beta_r``, ``beta_tt``, ``gamma_tt``), checked against
``schemas/bcsdf-preset.schema.json``.

- ``bcsdf_presets()`` -> the bundled preset names;
- ``read_bcsdf_preset(name)`` -> (path, document), refusing an unknown name or an invalid file (LoomError);
- ``load_bcsdf_preset(name)`` -> the packed BCSDF row (``stages.core.shading.bcsdf.pack_bcsdf``);
- ``check_bcsdf_names(scene, options)`` -> every preset a scene and ``--bcsdf`` name exists and is valid.

Scene checking (``pipeline.scene``) and render set-up (``pipeline.render_setup``, the renderers) both read them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import LoomError
from .schemas import validate
from .toml_file import read_toml

BCSDF_DIR = Path(__file__).resolve().parents[1] / "data" / "bcsdf"


def bcsdf_presets() -> list[str]:
    return sorted(p.stem for p in BCSDF_DIR.glob("*.toml"))


def read_bcsdf_preset(name: str) -> tuple[Path, dict]:
    path = Path(name)
    if path.suffix != ".toml" or not path.exists():
        path = BCSDF_DIR / f"{name}.toml"
    if not path.exists():
        raise LoomError(None, "bcsdf", f"unknown BCSDF preset {name!r} (known: {', '.join(bcsdf_presets())})")
    doc = read_toml(path, what="BCSDF preset")
    validate(doc, "bcsdf-preset", path)
    return path, doc


def load_bcsdf_preset(name: str) -> np.ndarray:
    """Packed BCSDF parameters of preset ``name`` (a name in data/bcsdf/ or a .toml path)."""
    from stages.core.shading.bcsdf import pack_bcsdf

    _, d = read_bcsdf_preset(name)
    return pack_bcsdf(d["c_r"], d["c_tt"], d["beta_r"], d["beta_tt"], d["gamma_tt"])


def check_bcsdf_names(scene, options) -> None:
    """Every BCSDF preset the scene names (``yarns.<group>.bcsdf`` of each fabric, a ``.toml`` path resolved against the
    scene) and ``--bcsdf`` exists and is valid, whether or not a yarn of the fabric uses it."""
    named = [(f"{part.yarns_key}.{g}.bcsdf", t["bcsdf"]) for part in scene.parts
             for g, t in sorted(part.yarns.items()) if t.get("bcsdf")]
    for place, name in named:
        try:
            read_bcsdf_preset(str(scene.resolve(name)) if name.endswith(".toml") else name)
        except LoomError as e:
            if e.file is not None:  # the preset file itself is broken: its own message names it
                raise
            raise LoomError(scene.path, place, e.message) from None
    if options.get("bcsdf"):
        try:
            read_bcsdf_preset(options["bcsdf"])
        except LoomError as e:
            if e.file is not None:
                raise
            raise LoomError(None, "--bcsdf", e.message) from None
