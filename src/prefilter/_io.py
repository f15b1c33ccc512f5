"""Atomic writes and chunk checkpoints for long bakes.

A bake writes each finished chunk to ``<out>.parts/<chunk>.npz`` (atomically), so a killed bake
restarts from the last finished chunk; the final output is written to a temporary file in the same
directory and renamed over the target, so readers never see a half-written file.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is renamed onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=suffix or "".join(path.suffixes) or ".tmp", dir=path.parent
    )
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp creates 0600 files; outputs (tables, package data) should be readable like any file.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield tmp
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def save_npz_atomic(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """``np.savez`` (uncompressed, deterministic bytes) written atomically."""
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)


def save_json_atomic(path: str | os.PathLike, obj) -> None:
    with atomic_path(path, suffix=".json") as tmp:
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n")


class Checkpoints:
    """Per-chunk results of a bake, stored beside its output in ``<out>.parts/``.

    ``key`` identifies the bake's settings: parts written under other settings are discarded.
    """

    def __init__(self, out: str | os.PathLike, key: dict):
        self.dir = Path(str(out) + ".parts")
        self.key = json.dumps(key, sort_keys=True)
        meta = self.dir / "settings.json"
        if self.dir.exists():
            try:
                same = meta.read_text() == self.key
            except OSError:
                same = False
            if not same:
                shutil.rmtree(self.dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        if not meta.exists():
            with atomic_path(meta, suffix=".json") as tmp:
                tmp.write_text(self.key)

    def _file(self, chunk: int) -> Path:
        return self.dir / f"{chunk:06d}.npz"

    def done(self, chunk: int) -> bool:
        return self._file(chunk).exists()

    def save(self, chunk: int, **arrays: np.ndarray) -> None:
        save_npz_atomic(self._file(chunk), **arrays)

    def load(self, chunk: int) -> dict[str, np.ndarray]:
        with np.load(self._file(chunk)) as z:
            return {k: z[k] for k in z.files}

    def clear(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)
