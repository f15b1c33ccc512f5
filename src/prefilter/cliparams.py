"""Click parameter types the commands share: seeds and output paths, checked while the command
line is parsed, so that a bad value stops a command before its work rather than after it.

``SEED`` takes integers in ``[0, 2**63)`` (NumPy's ``SeedSequence`` rejects negative seeds).
``OutputFile()`` / ``OutputDir()`` are ``click.Path`` types that also check that the file (or
folder) can be created there: :func:`check_writable` creates and removes a probe file in the
nearest existing folder, which also catches what permission bits do not show (``/proc``,
read-only mounts, a file where a folder is expected).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import click

from prefilter.errors import PrefilterError

__all__ = ["SEED", "SEED_MAX", "OutputDir", "OutputFile", "check_writable", "scheduler_options"]

#: The largest seed the commands take.
SEED_MAX = 2**63 - 1


def check_writable(path: str | os.PathLike, *, directory: bool = False) -> Path:
    """``path`` as a :class:`~pathlib.Path` if a file (``directory=True``: a folder) can be
    written there; otherwise a :class:`PrefilterError` naming ``path``.

    Missing parent folders are fine when the nearest existing one accepts new entries (the
    writers create them). Nothing is left behind.
    """
    p = Path(path)
    if p.is_dir() and not directory:
        raise PrefilterError(f"{p}: cannot write a file here: it is a folder")
    if p.exists() and not p.is_dir() and directory:
        raise PrefilterError(f"{p}: cannot write a folder here: it is a file")
    folder = Path(os.path.abspath(p if directory else p.parent))
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise PrefilterError(f"{p}: cannot write here: {folder} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".prefilter-probe-", dir=folder)
    except OSError as exc:
        raise PrefilterError(f"{p}: cannot write here: {folder} does not accept new files "
                             f"({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)
    return p


class _Seed(click.ParamType):
    name = "integer"

    def convert(self, value, param, ctx):
        if isinstance(value, int) and not isinstance(value, bool):
            v = value
        else:
            try:
                v = int(str(value), 10)
            except ValueError:
                self.fail(f"expected an integer seed >= 0, got {value!r}", param, ctx)
        if not 0 <= v <= SEED_MAX:
            self.fail(f"expected an integer seed in [0, 2**63), got {v}", param, ctx)
        return v


#: A random seed: an integer in ``[0, 2**63)``.
SEED = _Seed()


class OutputFile(click.Path):
    """A ``click.Path`` for a file the command writes: checked by :func:`check_writable`."""

    def __init__(self, path_type=None):
        super().__init__(dir_okay=False, path_type=path_type)

    def convert(self, value, param, ctx):
        value = super().convert(value, param, ctx)
        try:
            check_writable(value)
        except PrefilterError as exc:
            self.fail(str(exc), param, ctx)
        return value


class OutputDir(click.Path):
    """A ``click.Path`` for a folder the command writes into: checked by :func:`check_writable`."""

    def __init__(self, path_type=None):
        super().__init__(file_okay=False, path_type=path_type)

    def convert(self, value, param, ctx):
        value = super().convert(value, param, ctx)
        try:
            check_writable(value, directory=True)
        except PrefilterError as exc:
            self.fail(str(exc), param, ctx)
        return value


def scheduler_options(command):
    """``--scheduler`` and ``--workers`` (alias ``-j``, ``--processes``) of a command whose work
    runs as independent tasks (:class:`prefilter.distributed.Engine`); the command receives
    ``scheduler`` and ``workers`` (``None`` when not given)."""
    command = click.option(
        "--workers", "-j", "--processes", "workers", type=click.IntRange(1, 4096), default=None,
        help="Worker processes of a local cluster on this machine (--scheduler local; "
             "default: the cores); more than 1 without --scheduler starts one.")(command)
    return click.option(
        "--scheduler", default=None, metavar="ADDRESS",
        help="Where the tasks run: 'synchronous' (this process), 'local' (a local Dask cluster) "
             "or a dask.distributed scheduler address such as tcp://host:8786 (default: "
             "$DASK_SCHEDULER_ADDRESS, else this process). Results are checkpointed: rerun "
             "to resume.")(command)
