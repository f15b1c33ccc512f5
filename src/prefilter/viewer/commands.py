"""``prefilter view`` and ``prefilter export``: the WebGL2 viewer from the command line (thin
layers over :func:`prefilter.viewer.export_scene` and :func:`prefilter.viewer.serve`)."""

from __future__ import annotations

import shutil
import tempfile

import click

from prefilter.cliparams import OutputDir


def _table_options(f):
    f = click.option("--aniso-table", type=click.Path(exists=True, dir_okay=False), default=None,
                     help="Anisotropic LTC table .npz (`prefilter bake ltc-aniso`; default: "
                          "the shipped one).")(f)
    return click.option("--iso-table", type=click.Path(exists=True, dir_okay=False), default=None,
                        help="Isotropic LTC table .npz (`prefilter bake ltc-iso`; default: the "
                             "shipped one).")(f)


def _load_tables(iso, aniso) -> dict:
    from prefilter.ltc.aniso.table import AnisoGGXTable
    from prefilter.ltc.table import GGXTable

    return {"iso_table": GGXTable.load(iso) if iso else None,
            "aniso_table": AnisoGGXTable.load(aniso) if aniso else None}


@click.command("export", short_help="Write the viewer of a scene as a static web folder.")
@click.argument("scene", required=False, type=click.Path(exists=True, dir_okay=False))
@click.option("--out", "-o", "out", required=True, type=OutputDir(),
              help="Folder to write (page + data); it opens from any static web server.")
@click.option("--no-builtin-maps", is_flag=True,
              help="Leave out the procedural normal maps of the page's normal-map choice.")
@_table_options
def export(scene, out, no_builtin_maps, iso_table, aniso_table):
    """Write the viewer for SCENE (a scene JSON, docs/scenes.md; default: a plane and a sphere
    under a quad light) as a static folder."""
    from prefilter.viewer.export import export_scene

    path = export_scene(scene, out, builtin_maps=not no_builtin_maps,
                        **_load_tables(iso_table, aniso_table))
    click.echo(f"wrote {path} (serve it, e.g. `python -m http.server -d {path}`)")


@click.command("view")
@click.argument("scene", required=False, type=click.Path(exists=True, dir_okay=False))
@click.option("--port", default=8000, show_default=True, type=click.IntRange(0, 65535),
              help="Port on 127.0.0.1 (0: any free port).")
@click.option("--no-browser", is_flag=True, help="Only print the URL.")
@_table_options
def view(scene, port, no_browser, iso_table, aniso_table):
    """Serve the WebGL2 viewer of SCENE (default: a plane and a sphere under a quad light)."""
    from prefilter.viewer.export import export_scene
    from prefilter.viewer.server import serve

    import signal
    import sys

    # SIGTERM ends the server like Ctrl-C, so the temporary folder is removed
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    tmp = tempfile.mkdtemp(prefix="prefilter-view-")
    try:
        export_scene(scene, tmp, **_load_tables(iso_table, aniso_table))
        server, url = serve(tmp, port, background=False)
        click.echo(f"serving {url} (Ctrl-C to stop)", err=False)
        if not no_browser:
            import webbrowser

            webbrowser.open(url)
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass
        finally:
            server.server_close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
