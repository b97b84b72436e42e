"""CLI contract: every subcommand has real --help (exit 0), usage errors exit 2 with one reason,
and success exits 0."""
import pytest

from pipeline.cli import app


def _commands():
    import typer.main

    return sorted(typer.main.get_command(app).commands)


def test_stage_commands_present():
    cmds = set(_commands())
    assert {"ingest", "info", "inspect", "tables", "realize", "lookup", "export", "render", "voxelize",
            "tile", "evaluate"} <= cmds


@pytest.mark.parametrize("name", _commands())
def test_every_command_has_help(cli, name):
    code, out, err = cli(name, "--help")
    assert code == 0 and "Usage" in out and len(out.splitlines()) > 5


def test_usage_errors_exit_2(cli):
    code, _, err = cli("ingest")
    assert code == 2 and "Missing argument" in err
    code, _, err = cli("ingest", "x.bcc", "-o", "y.zarr", "--bogus")
    assert code == 2 and "No such option" in err
    code, _, err = cli("info", "does-not-exist.zarr")
    assert code == 2 and "does-not-exist.zarr" in err and "not found" in err
