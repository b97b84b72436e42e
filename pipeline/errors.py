"""Errors a user can act on. The CLI prints them as one line and exits with code 2."""
from __future__ import annotations

import difflib
from pathlib import Path


class LoomError(Exception):
    """Bad input: names the file, the place in it, and what is wrong.

    ``file`` is the file at fault (a scene, an artifact, a preset); ``place`` the dotted key in it
    (``yarns.warp.preset``), or, with no file, the command-line option the user typed (``--method``,
    ``--set tint``). ``one_line`` is ``FILE: PLACE: message`` -- or ``OPTION: message`` for an option.
    """

    exit_code = 2

    def __init__(self, file: str | Path | None, place: str | None, message: str):
        self.file = str(file) if file is not None else None
        self.place = place
        self.message = message
        super().__init__(self.one_line())

    def __reduce__(self):  # picklable (a chunk task's error crosses from a Dask worker)
        return (self.__class__, (self.file, self.place, self.message))

    def one_line(self) -> str:
        msg = " ".join(str(self.message).split())
        return ": ".join([p for p in (self.file, self.place) if p] + [msg])


class IncompleteArtifact(LoomError):
    """An artifact directory exists but was never marked complete."""


def did_you_mean(name, known) -> str:
    """``"; did you mean 'cotton1'?"`` for the nearest of ``known`` to ``name`` (difflib), else ``""``."""
    close = difflib.get_close_matches(str(name), [str(k) for k in known], n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def unknown(what: str, name, known) -> str:
    """The message for a name that names nothing: ``unknown preset 'coton1' (known: cotton1, cotton2);
    did you mean 'cotton1'?``."""
    known = list(known)
    return f"unknown {what} {name!r} (known: {', '.join(map(str, known)) or 'none'})" + did_you_mean(name, known)


def check_name(name, known, file, place: str, what: str) -> None:
    """Raise ``LoomError(file, place, unknown(what, name, known))`` unless ``name`` is one of ``known``."""
    known = list(known)
    if name not in known:
        raise LoomError(file, place, unknown(what, name, known))
