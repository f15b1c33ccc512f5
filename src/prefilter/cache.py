"""The on-disk caches prefilter writes: where each lives, its size, and clearing it
(``prefilter cache``, ``prefilter cache clear [NAME]``).

A package that writes a cache registers it in :data:`CACHES` by name, with the import path of a
function returning its directory (strings, as the render methods' registry: listing the caches
imports no method package until asked). Every cache is safe to delete: what it holds is rebuilt
on first use (a glints bake, a kernel compilation), at that cost.
"""

from __future__ import annotations

import importlib
import shutil
from dataclasses import dataclass
from pathlib import Path

import click

from prefilter.errors import PrefilterError

#: name -> (``"module:function"`` returning the cache's directory, what it holds)
CACHES: dict[str, tuple[str, str]] = {
    "glints": ("prefilter.glints.bake:cache_dir",
               "baked glints NDF pyramids and Wang-tile maps ($PREFILTER_GLINTS_CACHE)"),
    "numba": ("prefilter.cache:numba_cache_dir",
              "compiled Numba kernels, one folder per source fingerprint "
              "($PREFILTER_NUMBA_CACHE, $NUMBA_CACHE_DIR)"),
}


def numba_cache_dir() -> Path:
    """The folder of the compiled kernels of every source version
    (:func:`prefilter.jit.cache_dir` without the fingerprint), or ``$NUMBA_CACHE_DIR``."""
    import os

    from prefilter import jit

    d = jit.cache_dir()
    return Path(os.environ["NUMBA_CACHE_DIR"]) if d is None else d.parent


@dataclass(frozen=True)
class CacheInfo:
    """One cache: its ``name``, ``path``, ``description``, ``size`` in bytes and ``files``."""

    name: str
    path: Path
    description: str
    size: int
    files: int


def _directory(name: str) -> Path:
    module, func = CACHES[name][0].split(":")
    return Path(getattr(importlib.import_module(module), func)())


def _usage(path: Path) -> tuple[int, int]:
    """Bytes on disk (allocated blocks: sparse files count what they hold) and file count."""
    size = files = 0
    if path.is_dir():
        for f in path.rglob("*"):
            try:
                if f.is_file() and not f.is_symlink():
                    st = f.stat()
                    size += getattr(st, "st_blocks", 0) * 512 or st.st_size
                    files += 1
            except OSError:  # removed while walking (another process clearing or baking)
                pass
    return size, files


def info(name: str) -> CacheInfo:
    """The :class:`CacheInfo` of the registered cache ``name``."""
    if name not in CACHES:
        raise PrefilterError(f"NAME: expected one of {sorted(CACHES)}, got {name!r}")
    path = _directory(name)
    size, files = _usage(path)
    return CacheInfo(name, path, CACHES[name][1], size, files)


def caches() -> list[CacheInfo]:
    """Every registered cache, in name order."""
    return [info(n) for n in sorted(CACHES)]


def clear(name: str) -> CacheInfo:
    """Delete the contents of cache ``name`` (the folder itself stays); returns what it held."""
    before = info(name)
    if before.path.is_dir():
        for f in before.path.iterdir():
            if f.is_dir() and not f.is_symlink():
                shutil.rmtree(f, ignore_errors=True)
            else:
                f.unlink(missing_ok=True)
    return before


def human(n: int) -> str:
    """``n`` bytes as ``"12.3 MiB"``."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"  # pragma: no cover - the loop returns


@click.group("cache", invoke_without_command=True)
@click.pass_context
def cache_command(ctx) -> None:
    """List the on-disk caches (path, size) or clear them."""
    if ctx.invoked_subcommand is None:
        ctx.invoke(list_command)


@cache_command.command("list")
def list_command() -> None:
    """Each cache: name, size, files, path and what it holds."""
    for c in caches():
        click.echo(f"{c.name:8s} {human(c.size):>10s} {c.files:6d} files  {c.path}\n"
                   f"{'':8s} {c.description}")


@cache_command.command("clear")
@click.argument("name", required=False)
def clear_command(name: str | None) -> None:
    """Delete the contents of cache NAME (default: every cache)."""
    for n in [name] if name else sorted(CACHES):
        c = clear(n)
        click.echo(f"{c.name}: removed {human(c.size)} ({c.files} files) from {c.path}")
