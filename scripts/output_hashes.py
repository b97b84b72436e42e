"""Hashes of a directory of loomlight outputs, for refactors that must not change one output byte.

    make demo OUT=/tmp/a && scripts/refactor_extras.sh /tmp/a      # before the change
    .venv/bin/python scripts/output_hashes.py /tmp/a > hashes.txt
    make demo OUT=/tmp/b && scripts/refactor_extras.sh /tmp/b      # after
    .venv/bin/python scripts/output_hashes.py /tmp/b | diff hashes.txt -   # no lines differ

Images and arrays (.exr, .png, .npy, .txt) are hashed as files, .npz archives by their arrays. An
artifact (a zarr directory) is hashed by its arrays (name, dtype, shape, bytes) and its summary
without the fields that measure the run rather than the result (times, rates, peak memory, thread
count, paths on disk, including the ``source`` path a voxel grid records). Reports (.md, .html) are
skipped: they quote timings.
"""
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

VOLATILE = ("_s", "_per_s", "peak_memory_bytes", "threads", "created", "exr", "png", "scene", "path", "source")


def _steady(obj):
    if isinstance(obj, dict):
        return {k: _steady(v) for k, v in sorted(obj.items())
                if not (k.endswith(VOLATILE) or k in VOLATILE or k.endswith("_time_s"))}
    if isinstance(obj, list):
        return [_steady(v) for v in obj]
    return obj


def artifact_hash(path: Path) -> str:
    import zarr

    from pipeline.artifacts import hash_arrays

    g = zarr.open_group(str(path), mode="r")
    h = hashlib.sha256()
    h.update(json.dumps(_steady(dict(g.attrs).get("summary", {})), sort_keys=True).encode())
    hash_arrays(g, h)
    return h.hexdigest()


def main(root: str) -> None:
    root = Path(root)
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root)
        if any(part.endswith(".zarr") for part in rel.parts[:-1]):
            continue
        if p.is_dir() and p.suffix == ".zarr":
            print(f"{artifact_hash(p)}  {rel}")
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
