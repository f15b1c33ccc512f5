"""The ``prefilter`` command line: a thin layer over the library.

Subcommands live next to the code they drive (``<package>/commands.py``) and are imported lazily,
so ``prefilter --help`` is fast and a missing optional dependency only affects its own command.
A problem of input, files or environment (:class:`~prefilter.errors.PrefilterError`, ``OSError``,
a usage error) becomes a one-line message and exit code 2; anything else is a bug and keeps its
traceback.
"""

from __future__ import annotations

import importlib
import sys
import warnings

import click

from prefilter.errors import PrefilterError


class LazyGroup(click.Group):
    """A click group whose subcommands are ``"module:attribute"`` strings loaded on use."""

    def __init__(self, *args, lazy: dict[str, str] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy = dict(lazy or {})

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(self.lazy))

    def get_command(self, ctx, name):
        if name in self.lazy:
            module, attr = self.lazy[name].split(":")
            try:
                return getattr(importlib.import_module(module), attr)
            except (ImportError, AttributeError) as exc:
                reason = f"command '{name}' is unavailable: {exc}"

                def unavailable():
                    raise click.ClickException(reason)

                return click.Command(name, callback=unavailable, short_help="(unavailable)")
        return super().get_command(ctx, name)


BAKE_COMMANDS = {
    "ltc-iso": "prefilter.ltc.commands:bake_ltc_iso",
    "ltc-aniso": "prefilter.ltc.aniso.commands:bake_ltc_aniso",
    "colormap": "prefilter.colormap.commands:bake_colormap",
    "leadr": "prefilter.leadr.commands:bake_leadr",
    "glints": "prefilter.glints.commands:bake_glints",
    "glints-wang": "prefilter.glints.commands:bake_glints_wang",
    "glints-wave": "prefilter.glints.commands:bake_glints_wave",
    "roughness": "prefilter.roughness.commands:bake_roughness_cmd",
}

TOP_COMMANDS = {
    "render": "prefilter.render.commands:render",
    "compare": "prefilter.render.commands:compare",
    "export-mitsuba": "prefilter.render.commands:export_mitsuba",
    "demo": "prefilter.report.demo:demo",
    "validate": "prefilter.ltc.commands:validate",
    "export-ltc": "prefilter.ltc.commands:export_ltc",
    "multiscale-fit": "prefilter.multiscale.commands:multiscale_fit",
    "view": "prefilter.viewer.commands:view",
    "export": "prefilter.viewer.commands:export",
    "examples": "prefilter.examples.commands:examples",
    "cache": "prefilter.cache:cache_command",
}


@click.group(cls=LazyGroup, lazy=TOP_COMMANDS)
@click.version_option(package_name="prefilter")
def cli() -> None:
    """prefilter: prefiltered shading for area lights, normal maps, colour maps and glints."""


@cli.group(cls=LazyGroup, lazy=BAKE_COMMANDS)
def bake() -> None:
    """Fit or precompute tables and maps (resumable, atomic writes)."""


def _one_line(text: str) -> str:
    return " ".join(line.strip() for line in str(text).splitlines() if line.strip())


def _fail(message: str) -> None:
    click.echo(f"prefilter: error: {_one_line(message)}", err=True)
    sys.exit(2)


def main(argv: list[str] | None = None) -> None:
    """Run the command line. Problems of input, files and environment (PrefilterError, OSError,
    MemoryError, usage errors) print one line and exit 2; any other exception is a bug and keeps
    its traceback. Warnings are held back until the command ends and shown only on success, so
    an error message is the last and only line a failed command prints."""
    with warnings.catch_warnings(record=True) as caught:
        try:
            rc = cli.main(args=argv, prog_name="prefilter", standalone_mode=False)
        except PrefilterError as exc:
            _fail(str(exc))
        except click.exceptions.Abort:
            click.echo("prefilter: aborted", err=True)
            sys.exit(130)
        except click.exceptions.NoArgsIsHelpError as exc:
            exc.show()  # a bare group: its help, as click prints it
            sys.exit(exc.exit_code)
        except click.UsageError as exc:
            # a missing or unknown argument points to the help; a bad value speaks for itself
            bad_value = (isinstance(exc, click.BadParameter)
                         and not isinstance(exc, click.MissingParameter))
            hint = (f" (see '{exc.ctx.command_path} --help')"
                    if exc.ctx is not None and not bad_value else "")
            _fail(exc.format_message() + hint)
        except click.ClickException as exc:
            _fail(exc.format_message())
        except OSError as exc:
            where = f": {exc.filename}" if exc.filename else ""
            _fail(f"{exc.strerror or exc}{where}")
        except MemoryError:
            _fail("out of memory")
    for w in caught:
        warnings.showwarning(w.message, w.category, w.filename, w.lineno, w.file, w.line)
    sys.exit(rc if isinstance(rc, int) else 0)


if __name__ == "__main__":  # pragma: no cover
    main()
