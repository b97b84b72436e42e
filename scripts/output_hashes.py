"""Hashes of a directory of loomlight outputs, for refactors that must not change one output byte.

    make demo OUT=/tmp/a && scripts/refactor_extras.sh /tmp/a      # before the change
    .venv/bin/python scripts/output_hashes.py /tmp/a > hashes.txt
    mv /tmp/a /tmp/a.before
    make demo OUT=/tmp/a && scripts/refactor_extras.sh /tmp/a      # after, into the same directory
    .venv/bin/python scripts/output_hashes.py /tmp/a | diff hashes.txt -   # no lines differ

(The same directory: a few pictures print an artifact's path in their titles.)

Images and arrays (.exr, .png, .npy, .txt) are hashed as files, .npz archives by their arrays. An
artifact (a zarr directory) is hashed by its arrays (name, dtype, shape, bytes) and its summary without
the fields that measure the run rather than the result (times, rates, peak memory, thread count, paths on
disk, including the ``source`` path a voxel grid records; cache keys and input identities, which hash the
code and the paths), and with the output directory in any recorded string written as ``<OUT>``, so two
runs into different directories compare. Reports (.md, .html) are skipped: they quote timings. So are
the products of the equal-time comparison (``TIMED``): it gives each method the samples that fit a
measured time, and its convergence fit divides by measured seconds.
"""
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

VOLATILE = ("_s", "_per_s", "peak_memory_bytes", "threads", "created", "exr", "png", "scene", "path", "source",
            "key", "source_hash")
TIMED = ("compare/equal_time", "compare/convergence.png", "compare/evaluation.zarr")


def _steady(obj, root=""):
    if isinstance(obj, dict):
        return {k: _steady(v, root) for k, v in sorted(obj.items())
                if not (k.endswith(VOLATILE) or k in VOLATILE or k.endswith("_time_s"))}
    if isinstance(obj, list):
        return [_steady(v, root) for v in obj]
    if isinstance(obj, str) and root:
        return obj.replace(root, "<OUT>")
    return obj


def artifact_hash(path: Path, root: Path) -> str:
    import zarr

    from pipeline.artifacts import hash_arrays

    g = zarr.open_group(str(path), mode="r")
    h = hashlib.sha256()
    h.update(json.dumps(_steady(dict(g.attrs).get("summary", {}), str(root)), sort_keys=True).encode())
    hash_arrays(g, h)
    return h.hexdigest()


def main(root: str) -> None:
    root = Path(root)
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root)
        if any(part.endswith(".zarr") for part in rel.parts[:-1]) or str(rel).startswith(TIMED):
            continue
        if p.is_dir() and p.suffix == ".zarr":
            print(f"{artifact_hash(p, root)}  {rel}")
        elif p.is_file() and p.suffix == ".npz":  # a zip: its entries carry the time they were written
            h = hashlib.sha256()
            with np.load(p) as z:
                for name in sorted(z.files):
                    h.update(f"{name}:{z[name].dtype}:{z[name].shape}".encode())
                    h.update(np.ascontiguousarray(z[name]).tobytes())
            print(f"{h.hexdigest()}  {rel}")
        elif p.is_file() and p.suffix in (".exr", ".png", ".npy", ".txt"):
            print(f"{hashlib.sha256(p.read_bytes()).hexdigest()}  {rel}")


if __name__ == "__main__":
    main(sys.argv[1])
