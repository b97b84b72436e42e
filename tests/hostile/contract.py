"""The bad-input contract the hostile-input tests check (DEVELOPERS.md, "Bad input"), shared by the
test files of issue 58: exit code 2, exactly one line on stderr starting ``error: `` that names the
file or option and the place, no traceback, and nothing lost -- the workspace (reference: the sha256
of every file in it, taken before the command) byte for byte as it was, with no half-written sibling
left beside an output. ``forge`` makes the forged artifacts: a summary edited and its content hash
recomputed, as a tool (or a person) that knows the hash would."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path


def snapshot(root: Path) -> dict:
    """Every path under root: sha256 of a file's bytes, '<dir>' for a directory, '-> target' for a link."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = os.path.join(dirpath, name)
            rel = os.path.relpath(p, root)
            if os.path.islink(p):
                out[rel] = "-> " + os.readlink(p)
            elif os.path.isdir(p):
                out[rel] = "<dir>"
            else:
                out[rel] = hashlib.sha256(Path(p).read_bytes()).hexdigest()
    return out


def assert_refused(cli, workspace: Path, args, *names) -> str:
    """Run the CLI; assert the contract (module doc) and that the error line names every one of
    ``names``; returns the line."""
    before = snapshot(workspace)
    code, out, err = cli(*args)
    lines = err.strip().splitlines()
    assert code == 2, (code, out, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for n in names:
        assert str(n) in lines[0], (n, lines[0])
    assert "Traceback" not in err + out
    assert snapshot(workspace) == before
    return lines[0]


def forge(src: Path, dst: Path, edit, rehash: bool = True) -> Path:
    """Copy artifact ``src`` to ``dst``, apply ``edit(attributes)`` to its root attributes (``summary``,
    ``loomlight``) and, with ``rehash``, recompute its content hash over the edited summary and
    parameters (``pipeline.artifacts.content_digest``)."""
    from pipeline.artifacts import content_digest

    shutil.copytree(src, dst)
    doc = json.loads((dst / "zarr.json").read_text())
    attrs = doc["attributes"]
    edit(attrs)
    meta = attrs["loomlight"]
    if rehash:
        meta["content_hash"] = content_digest(meta["kind"], attrs["summary"], meta["arrays"], meta["params"])
    (dst / "zarr.json").write_text(json.dumps(doc))
    return dst
