"""``prefilter examples``: list the shipped example scenes, or print one (thin layer over
:mod:`prefilter.examples`)."""

from __future__ import annotations

import click


@click.command("examples")
@click.argument("name", required=False)
def examples(name: str | None) -> None:
    """List the example scenes (render one with `prefilter render example:NAME`), or print
    example NAME's scene JSON to copy and edit."""
    from prefilter.examples import EXAMPLES, PREFIX, path

    if name is not None:
        click.echo(path(name.removeprefix(PREFIX)).read_text(encoding="utf-8"), nl=False)
        return
    width = max(map(len, EXAMPLES)) + len(PREFIX)
    for n, line in EXAMPLES.items():
        click.echo(f"{PREFIX + n:<{width}}  {line}")
