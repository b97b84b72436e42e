"""`--help` says the choices (issue 23 item 3): `render --method` and `--source` list the renderer
registry's methods and sources, no flag is shown as taking a `<bool>` value, every command summary is
one whole sentence, and the top-level help names only stages that have a command."""
import re

import pytest
import typer

from pipeline.cli import command
from pipeline.renderers import METHODS

ROOT_CMD = command()


def _commands(cmd=ROOT_CMD, prefix=()):
    """(argv prefix, click command) of every command and sub-command."""
    for name, sub in sorted(cmd.commands.items()):
        yield (*prefix, name), sub
        if isinstance(sub, typer.core.TyperGroup):
            yield from _commands(sub, (*prefix, name))


ALL = [((), ROOT_CMD), *_commands()]


def _help(cli, monkeypatch, *argv):
    monkeypatch.setenv("COLUMNS", "240")  # rich wraps at the console width; wide enough for one line per row
    code, out, err = cli(*argv, "--help")
    assert code == 0, err
    return out


def _row(out, option):
    """The help table row of ``option`` (its first line)."""
    rows = [line for line in out.splitlines() if re.search(rf"│\s+(\*\s+)?{option}\s", line)]
    assert len(rows) == 1, (option, out)
    return rows[0]


def test_render_method_and_source_list_the_registry(cli, monkeypatch):
    out = _help(cli, monkeypatch, "render")
    methods = list(METHODS)
    sources = list(dict.fromkeys(s.name for m in METHODS.values() for s in m.sources))
    assert f"<{' | '.join(methods)}>" in _row(out, "--method")
    assert f"<{' | '.join(sources)}>" in _row(out, "--source")
    for m in METHODS.values():   # and the help text says each method and its sources
        assert m.name in out and all(s.name in out for s in m.sources)


@pytest.mark.parametrize("argv,cmd", ALL, ids=lambda a: " ".join(a) if isinstance(a, tuple) else "")
def test_no_flag_shown_as_taking_a_value(cli, monkeypatch, argv, cmd):
    out = _help(cli, monkeypatch, *argv)
    assert "<bool>" not in out
    assert re.search(r"--help\s+Show this message and exit\.", out), out
    flags = [p for p in cmd.params if getattr(p, "is_flag", False)]
    for p in flags:
        assert re.search(rf"{p.opts[0]}\s+{re.escape(p.help.split()[0])}", out), (p.opts, out)


@pytest.mark.parametrize("argv,cmd", ALL[1:], ids=lambda a: " ".join(a) if isinstance(a, tuple) else "")
def test_command_summary_is_one_whole_sentence(argv, cmd):
    """The summary `loomlight --help` lists (the docstring's first paragraph) is one line: a capital, a
    verb and a full stop."""
    summary = cmd.help.strip().split("\n\n")[0]
    assert "\n" not in summary, summary
    assert summary[0].isupper() and summary.endswith("."), summary
    assert not re.match(r"^(Seed|Per|Full|Inside|Studies)\b", summary), summary   # the former noun phrases


def test_top_level_help_names_only_commands(cli, monkeypatch):
    out = _help(cli, monkeypatch)
    text = " ".join(out.split("╭─ Options")[0].split())
    commands = {argv[0] for argv, _ in _commands()}
    stage_words = commands | {"btf", "bysdf", "lafortune", "daubert", "ssdf", "svf", "iirtf", "lookup"}
    methods = re.findall(r"one of ([a-z_, ]+), and", text)[0].split(", ")
    for m in methods:   # the methods it names are registered
        assert m in METHODS
    named = {w for w in re.findall(r"[a-z_]+", text.replace(", ".join(methods), "")) if w in stage_words}
    assert named and named <= commands, named - commands
