"""Errors a user can act on. The CLI prints them as one line and exits with code 2."""
from __future__ import annotations

from pathlib import Path


class LoomError(Exception):
    """Bad input: names the file, the place in it, and what is wrong."""

    exit_code = 2

    def __init__(self, file: str | Path | None, place: str | None, message: str):
        self.file = str(file) if file is not None else None
        self.place = place
        self.message = message
        super().__init__(self.one_line())

    def one_line(self) -> str:
        where = self.file or "<input>"
        if self.place:
            where = f"{where}: {self.place}"
        msg = " ".join(str(self.message).split())
        return f"{where}: {msg}"


class IncompleteArtifact(LoomError):
    """An artifact directory exists but was never marked complete."""
