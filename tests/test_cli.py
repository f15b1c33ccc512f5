"""``prefilter.cli.main``: which exceptions become one line and exit 2, warnings held back until
success, and the help texts (command summaries, the list of render methods)."""

from __future__ import annotations

import re
import warnings

import click
import pytest
from click.testing import CliRunner

from prefilter.cli import cli, main
from prefilter.errors import PrefilterError


def _run(capfd, *args):
    capfd.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(list(args))
    out, err = capfd.readouterr()
    return (exc.value.code or 0), out, err


@pytest.fixture
def command():
    """Add a command ``t`` whose body is the function given, to the top-level group."""
    added = []

    def add(body):
        cli.add_command(click.Command("t", callback=body))
        added.append("t")

    yield add
    for name in added:
        cli.commands.pop(name, None)


@pytest.mark.parametrize("exc,words", [
    (PrefilterError("scene: expected\nsomething"), "scene: expected something"),
    (FileNotFoundError(2, "No such file or directory", "/x/y.exr"),
     "No such file or directory: /x/y.exr"),
    (PermissionError(13, "Permission denied", "/root/out.exr"), "Permission denied"),
    (OSError(28, "No space left on device"), "No space left on device"),
    (MemoryError(), "out of memory"),
    (click.ClickException("command 'x' is unavailable: no module"), "unavailable"),
])
def test_input_file_and_environment_errors_are_one_line(capfd, command, exc, words):
    def body():
        warnings.warn("printed only on success", RuntimeWarning)
        raise exc

    command(body)
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        rc, out, err = _run(capfd, "t")
    assert rc == 2 and not shown
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("prefilter: error: ") and words in lines[0], err
    assert "Traceback" not in err and "printed only on success" not in err


def test_a_bug_keeps_its_traceback(command):
    def body():
        raise ZeroDivisionError("a bug")

    command(body)
    with pytest.raises(ZeroDivisionError):
        main(["t"])


def test_warnings_are_shown_after_a_successful_command(capfd, command):
    def body():
        warnings.warn("kept for the end", RuntimeWarning)
        click.echo("done")

    command(body)
    with pytest.warns(RuntimeWarning, match="kept for the end"):
        rc, out, err = _run(capfd, "t")
    assert rc == 0 and out == "done\n"


def test_bare_group_prints_its_help(capfd):
    rc, _, err = _run(capfd, "bake")
    assert rc == 2 and "Commands:" in err and "ltc-iso" in err


def test_version_and_help_exit_0(capfd):
    assert _run(capfd, "--version")[0] == 0
    rc, out, _ = _run(capfd, "--help")
    assert rc == 0 and "render" in out


# ------------------------------------------------------------------------------------- help


def test_command_summaries_are_whole_sentences():
    """``prefilter --help`` shows each command's summary; none is cut inside a sentence at an
    abbreviation's period ("Verify eq.")."""
    out = CliRunner().invoke(cli, ["--help"], terminal_width=100).output
    lines = {m.group(1): m.group(2) for m in re.finditer(r"^  (\S+)\s+(.*)$", out, re.M)}
    assert "eq. 7" in lines["multiscale-fit"], lines["multiscale-fit"]
    assert not lines["multiscale-fit"].endswith("eq.")
    assert lines["export"].endswith("folder.")


def test_render_help_lists_every_method_with_a_line():
    from prefilter.render.methods import available, describe

    out = CliRunner().invoke(cli, ["render", "--help"]).output
    for name in available():
        line = next((ln for ln in out.splitlines() if ln.split()[:1] == [name]), None)
        assert line is not None, name
        parts = line.split(None, 1)  # a method registered without a description: its name alone
        assert len(parts) == 2 or not describe(name), (name, line)
        summary = parts[1] if len(parts) == 2 else ""
        assert describe(name).startswith(summary.removesuffix("...")), (name, summary)
        assert len(line) <= 80, line


def test_export_scene_is_optional(tmp_path):
    """``prefilter export --out DIR`` writes the default scene, as the README shows."""
    res = CliRunner().invoke(cli, ["export", "--out", str(tmp_path / "site"),
                                   "--no-builtin-maps"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "site/data/viewer.json").is_file()
