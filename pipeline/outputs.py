"""Output paths: the one check every command makes on its ``-o`` (and ``--png``, ``--write``,
``--export-npy``) before it does any work, given the command's inputs.

``check_output(path, option, kind, suffixes=())`` refuses, as one ``LoomError`` naming the path and
the option (exit code 2):

- a path in ``/proc`` or ``/sys`` (kernel file systems, not storage);
- a path under a regular file (``notes.txt/out.zarr``);
- a path whose nearest existing directory is not writable (read-only directory or file system);
  directories missing between it and the output are created by the writer, as ``make demo``
  relies on (``out/demo/...`` on a fresh clone);
- an output of the wrong kind that already exists: ``ARTIFACT`` replaces only a directory holding a
  ``zarr.json`` (an artifact is swapped in whole, so anything else would be deleted), ``FILE`` only
  a file, ``DIRECTORY`` only a directory;
- a suffix not in ``suffixes`` (``ARTIFACT`` paths end in ``.zarr``);
- an output that is one of the command's ``inputs``, lies inside one (a file written into an input
  artifact's directory) or, for an artifact (published by replacing the whole directory), holds one,
  whatever the path's form: relative, through symbolic links (both are resolved) or a hard link to
  the input (the same file).

Nothing is created or changed here: a refused command leaves the previous output untouched.
"""
from __future__ import annotations

import os
from pathlib import Path

from .errors import LoomError

ARTIFACT, FILE, DIRECTORY = "artifact", "file", "directory"
KERNEL_FILE_SYSTEMS = ("/proc", "/sys")


def _nearest_existing(path: Path) -> Path:
    p = path
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def _same_file(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist
        return False


def check_not_input(path, option: str, inputs, kind: str = FILE) -> None:
    """Refuse an output ``path`` that is one of ``inputs``, lies inside one or (``ARTIFACT``, published by
    replacing its whole directory) holds one; paths are resolved (relative paths, symbolic links) and
    existing files compared by identity (hard links)."""
    out = Path(os.path.realpath(path))
    for inp in inputs:
        if inp is None:
            continue
        real = Path(os.path.realpath(inp))
        if out == real or _same_file(path, inp):
            raise LoomError(path, option, f"is the input {inp}; writing it would destroy the input: choose "
                            "another path")
        if real in out.parents:
            raise LoomError(path, option, f"lies inside the input {inp}; writing it would change the input: "
                            "choose a path outside it")
        if kind == ARTIFACT and out in real.parents:
            raise LoomError(path, option, f"holds the input {inp}; publishing it would delete the input: "
                            "choose another path")


def check_output(path, option: str = "-o", kind: str = FILE, suffixes: tuple[str, ...] = (), inputs=()) -> Path:
    """``path`` as a Path once it can be written as an output of ``kind`` (module doc) and is none of
    ``inputs`` (nor inside one), else LoomError."""
    path = Path(path)
    if kind == ARTIFACT:
        suffixes = suffixes or (".zarr",)
    if suffixes and path.suffix.lower() not in suffixes:
        raise LoomError(path, option, f"the output must end in {' or '.join(suffixes)}")
    check_not_input(path, option, inputs, kind)
    real = Path(os.path.realpath(path))
    for fs in KERNEL_FILE_SYSTEMS:
        if real == Path(fs) or Path(fs) in real.parents:
            raise LoomError(path, option, f"cannot write under {fs} (a kernel file system, not storage)")
    parent = _nearest_existing(real.parent)
    if not parent.is_dir():
        raise LoomError(path, option, f"{parent} is a file, not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise LoomError(path, option, f"directory {parent} is not writable")
    if os.path.lexists(path):
        if kind == ARTIFACT and not (path / "zarr.json").is_file():
            what = "a directory without zarr.json" if path.is_dir() else "a file"
            raise LoomError(path, option, f"exists and is {what}, not an artifact; refusing to replace it")
        if kind == FILE and path.is_dir():
            raise LoomError(path, option, "is a directory; give a file name")
        if kind == DIRECTORY and not path.is_dir():
            raise LoomError(path, option, "exists and is not a directory")
    return path
