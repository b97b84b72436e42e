"""``loomlight info ARTIFACT [--json]``: what an artifact holds.

Shows its kind, summary (the stage's own numbers: counts, bounds, bytes, timings), array bytes,
parameters, inputs and provenance:

- ``wall_time_s``: the stage's whole run, from the runner's start (imports, reading inputs,
  compilation, compute) to the written artifact;
- ``compile_s``: numba compilation (or loading the compiled kernels from the cache) inside that run,
  where the stage recorded it (render: ``method_stats.compile_s``; precompute: ``compile_s``);
- ``content_hash``, ``build_key`` and every input's ``sha256`` in full, never cut short.

``--json`` prints one JSON object: the summary's keys, then the provenance (which replaces a summary
key of the same name: a render's summary times its renderer alone), every array's dtype, shape,
sha256 and crc32c (``arrays``) and each input's path, sha256 and stat fingerprint. The table shows
the same but the array checksums and the stat fingerprints, nested values as dotted rows
(``method_stats.compile_s``), floats to 6 significant digits; a long value (a hash) wraps onto more
lines, whole.

Reads metadata only (the artifact's zarr.json files): no array is loaded, numpy and zarr are not
imported; the table's caption and ``arrays_verified`` (``--json``) say so. ``--verify`` reads every
array, in blocks, and compares its bytes with the sha256 and crc32c recorded at write: a deleted,
truncated or garbled chunk is refused (exit code 2) naming the array.
"""
from __future__ import annotations

import json
from pathlib import Path

import typer


def compile_seconds(summary: dict):
    """The compilation time an artifact's stage recorded, or None."""
    if isinstance(summary.get("compile_s"), (int, float)):
        return summary["compile_s"]
    ms = summary.get("method_stats")
    if isinstance(ms, dict) and isinstance(ms.get("compile_s"), (int, float)):
        return ms["compile_s"]
    return None


def describe(path: Path, verify: bool = False) -> dict:
    """What ``info --json`` prints; ``verify``: read every array against its checksums first."""
    from ..artifacts import Artifact

    art = Artifact(path)
    if verify:
        art.verify()
    meta = art.meta
    doc = {"kind": art.kind, **{k: v for k, v in art.summary.items() if k not in _PROVENANCE},
           "path": str(path), "array_bytes": art.nbytes(), "stage": meta["stage"], "params": art.params,
           "inputs": meta["inputs"], "wall_time_s": meta["wall_time_s"]}
    cs = compile_seconds(art.summary)
    if cs is not None:
        doc["compile_s"] = cs
    doc.update({"peak_memory_bytes": meta["peak_memory_bytes"], "created": meta.get("created"),
                "loomlight_version": meta["loomlight_version"], "build_key": meta.get("build_key"),
                "content_hash": meta["content_hash"], "arrays": meta["arrays"], "arrays_verified": verify})
    return doc


# provenance keys a summary may also have (a render's summary times its renderer alone, before the
# writing): the artifact's provenance tells them for the whole stage
_PROVENANCE = ("wall_time_s", "compile_s", "peak_memory_bytes")


def _scalar(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    return str(v)


def _flat(value) -> bool:
    """A value shown in one row: a scalar, or a list of (lists of) scalars."""
    if isinstance(value, (list, tuple)):
        return all(_flat(v) for v in value)
    return not isinstance(value, dict)


def table_rows(doc: dict) -> list[tuple[str, str]]:
    """(key, value) rows of the table view: nested dicts and lists of dicts as dotted keys."""
    rows: list[tuple[str, str]] = []

    def add(key: str, v) -> None:
        if isinstance(v, dict):
            if not v:
                rows.append((key, "{}"))
            for k, sub in v.items():
                add(f"{key}.{k}", sub)
        elif isinstance(v, (list, tuple)) and not _flat(v):
            for i, sub in enumerate(v):
                add(f"{key}[{i}]", sub)
        elif key.endswith("_bytes") and isinstance(v, int) and not isinstance(v, bool):
            rows.append((key, f"{v} ({v / 2**20:.1f} MiB)"))
        else:
            rows.append((key, _scalar(v)))

    for k, v in doc.items():
        if k == "arrays_verified":  # the table's caption says it
            continue
        if k == "arrays":  # their sha256 and crc32c: --json
            for name, rec in v.items():
                rows.append((f"arrays.{name}", f"{rec['dtype']} {_scalar(rec['shape'])}"))
        elif k == "inputs":
            for name, rec in v.items():
                rows.append((f"inputs.{name}", str(rec.get("path"))))
                rows.append((f"inputs.{name}.sha256", str(rec.get("sha256"))))
        else:
            add(k, v)
    return rows


def register(app: typer.Typer) -> None:
    @app.command("info")
    def info(artifact: Path = typer.Argument(..., help="An artifact directory (*.zarr)."),
             as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
             verify: bool = typer.Option(False, "--verify", help="Read every array and check its bytes against the "
                                                                 "sha256 and crc32c recorded at write (without it, "
                                                                 "info reads metadata only).")):
        """Show an artifact's kind, summary numbers (counts, bounds, bytes), parameters and provenance."""
        doc = describe(artifact, verify)
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
            return
        from rich.console import Console
        from rich.table import Table
        from rich.text import Text

        caption = ("every array read: its bytes match the recorded sha256 and crc32c" if verify else
                   "arrays not read (metadata only): info --verify checks every array against its checksums")
        t = Table(title=f"{artifact} ({doc['kind']})", show_header=False, caption=caption)
        t.add_column("key", no_wrap=True)
        t.add_column("value", overflow="fold")
        for k, v in table_rows(doc):
            t.add_row(Text(k), Text(v))  # Text: a value's brackets are not rich markup
        Console().print(t)
