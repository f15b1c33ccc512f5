"""The ``prefilter`` command line: a thin layer over the library.

Subcommands live next to the code they drive (``<package>/commands.py``) and are imported lazily,
so ``prefilter --help`` is fast and a missing optional dependency only affects its own command.
Every :class:`~prefilter.errors.PrefilterError` becomes a one-line message and exit code 2.
"""

from __future__ import annotations

import importlib
import sys

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
}

TOP_COMMANDS = {
    "render": "prefilter.render.commands:render",
    "compare": "prefilter.render.commands:compare",
    "demo": "prefilter.report.demo:demo",
    "validate": "prefilter.ltc.commands:validate",
    "multiscale-fit": "prefilter.multiscale.commands:multiscale_fit",
    "view": "prefilter.viewer.commands:view",
    "export": "prefilter.viewer.commands:export",
    "cache": "prefilter.cache:cache_command",
}


@click.group(cls=LazyGroup, lazy=TOP_COMMANDS)
@click.version_option(package_name="prefilter")
def cli() -> None:
    """prefilter: prefiltered shading for area lights, normal maps, colour maps and glints."""


@cli.group(cls=LazyGroup, lazy=BAKE_COMMANDS)
def bake() -> None:
    """Fit or precompute tables and maps (resumable, atomic writes)."""


def main(argv: list[str] | None = None) -> None:
    try:
        rc = cli.main(args=argv, prog_name="prefilter", standalone_mode=False)
    except PrefilterError as exc:
        click.echo(f"prefilter: error: {exc}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo("prefilter: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    sys.exit(rc if isinstance(rc, int) else 0)


if __name__ == "__main__":  # pragma: no cover
    main()
