"""The ``loomlight`` command line.

Every module in ``pipeline.commands`` defines ``register(app)``; subcommands are discovered, so a
new stage adds one file. Bad input raises ``LoomError``: one line on stderr, exit code 2.

``--help``: every command's summary is the first line of its docstring, one whole sentence; a flag
shows no value type (``--force``, not ``--force <bool>``: ``command()``), and options that take a
name show the names they take (``render --method <fiberpath|...>``, from the renderer registry).

Last resort (the readers, runners and ``pipeline.outputs`` check input first): an ``OSError`` that
escapes them (disk full, a file vanishing under a run) is also one line and exit code 2. Any other
exception is a bug in loomlight: one line naming it and asking for a report, exit code 1, and with
``LOOMLIGHT_DEBUG=1`` the traceback too.
"""
from __future__ import annotations

import importlib
import os
import pkgutil
import sys

import typer

from . import __version__
from .errors import LoomError


def _help() -> str:
    from .renderers import known_methods

    return ("Render cloth at the level of its fibres. ingest reads yarn curves (a curve file, a WIF draft or a "
            "scene); tables builds procedural fibre tables from them, realize explicit fibres; tile lays fibre "
            "exemplars over a surface and precompute adds their light transport. render draws a scene with one of "
            f"{', '.join(known_methods())}, and evaluate compares renders. info and inspect show any artifact.")


app = typer.Typer(
    name="loomlight",
    help=_help(),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version(value: bool):
    if value:
        typer.echo(f"loomlight {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")):
    """Render cloth at the level of its fibres (the full text: ``_help``)."""


def _register_all() -> None:
    from . import commands

    for mod in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{mod.name}")
        if hasattr(module, "register"):
            module.register(app)


_register_all()


def command():
    """The click command ``loomlight`` runs: ``app`` with every flag (``--force``, ``--help``) shown in
    ``--help`` without a value type (typer would show ``<bool>``, as if the flag took a value)."""
    import typer.main

    cmd = typer.main.get_command(app)
    _plain_flags(cmd)
    return cmd


def _plain_flags(cmd) -> None:
    help_option = cmd.get_help_option(typer.Context(cmd))
    for p in [*cmd.params, *([help_option] if help_option is not None else [])]:
        if getattr(p, "is_flag", False) and p.metavar is None:
            p.metavar = ""
    for sub in getattr(cmd, "commands", {}).values():
        _plain_flags(sub)


NO_KERNELS = ("info", "docs")   # commands that never compile a kernel (no numba import for them)


def _watch_compilation(argv) -> None:
    """Announce numba compilations (``pipeline.compilation``) in a command that runs: not for ``--help``,
    ``--version`` or a command without kernels, which need not import numba."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] not in NO_KERNELS and not {"--help", "-h", "--version"} & set(args):
        from .compilation import watch

        watch()


def main(argv: list[str] | None = None) -> int:
    try:
        _watch_compilation(argv)
        code = command()(args=argv, standalone_mode=False)
        if isinstance(code, int) and not isinstance(code, bool) and code:
            return code   # without standalone mode click returns a command's typer.Exit(code) instead of raising it
    except LoomError as e:
        typer.echo(f"error: {e.one_line()}", err=True)
        return 2
    except typer.Exit as e:
        return int(e.exit_code or 0)
    except typer.Abort:
        typer.echo("aborted", err=True)
        return 1
    except OSError as e:
        where = e.filename if e.filename is not None else "<system>"
        typer.echo(f"error: {where}: {e.strerror or e}", err=True)
        _debug_traceback()
        return 2
    except Exception as e:
        # usage errors (missing argument, unknown option, bad value) from typer's bundled click:
        # they can show themselves; report them as bad input (exit code 2), anything else is a bug
        if hasattr(e, "show") and hasattr(e, "exit_code"):
            e.show()
            return 2
        msg = " ".join(str(e).split())[:200]
        typer.echo(f"error: internal error {type(e).__name__}: {msg} -- this is a loomlight bug, please report it "
                   f"(LOOMLIGHT_DEBUG=1 shows the traceback)", err=True)
        _debug_traceback()
        return 1
    return 0


def _debug_traceback() -> None:
    if os.environ.get("LOOMLIGHT_DEBUG", "") not in ("", "0"):
        import traceback

        traceback.print_exc()


def entry() -> None:  # pragma: no cover
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
