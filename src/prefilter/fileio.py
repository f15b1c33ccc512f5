"""Atomic writes, checksummed files and chunk checkpoints for long bakes.

A bake writes each finished chunk to ``<out>.parts/<chunk>.npz`` (atomically), so a killed bake
restarts from the last finished chunk; the final output is written to a temporary file in the same
directory and renamed over the target, so readers never see a half-written file.

Every ``.npz`` written by :func:`save_npz_atomic` carries a ``__meta__`` entry, a JSON string
``{"checksum": "sha256", "sha256": ..., "arrays": [...], "format": ..., "version": ...}`` whose
digest (:func:`array_digest`) covers the names, dtypes, shapes and bytes of all other arrays.
:func:`load_npz_checked` verifies it (files without ``__meta__``, written before checksums
existed, still load) and turns every decoding failure into a
:class:`~prefilter.errors.TableFileError` that names the file.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Mapping

import numpy as np

from prefilter.errors import TableFileError

#: Name of the checksum entry of a ``.npz`` written by :func:`save_npz_atomic`.
META_KEY = "__meta__"


@contextmanager
def exclusive_lock(path: str | os.PathLike) -> Iterator[None]:
    """Hold an exclusive advisory lock on the file ``path`` (created if missing) for the block.

    Two processes baking into the same output (pytest workers sharing the render cache, two
    shells) would otherwise share and delete each other's checkpoint parts. A waiting process
    blocks until the holder leaves. The lock file is unlinked on release; a waiter that then
    holds a lock on the unlinked file notices (inode changed) and locks the new one. Without
    ``fcntl`` (Windows) this is a no-op.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            try:
                same = os.stat(path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
        except BaseException:
            os.close(fd)
            raise
        if same:
            break
        os.close(fd)  # released by a holder that unlinked it: lock the current file
    try:
        yield
    finally:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
        os.close(fd)


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


def array_digest(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 of ``arrays`` in name order: each name, dtype, shape, then its C-order bytes."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(json.dumps([name, a.dtype.str, list(a.shape)]).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def json_digest(obj) -> str:
    """SHA-256 of the canonical JSON text of ``obj`` (sorted keys, no spaces)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":"))
                          .encode()).hexdigest()


def save_npz_atomic(path: str | os.PathLike, /, *, format_name: str | None = None,
                    format_version: int | None = None, **arrays: np.ndarray) -> None:
    """``np.savez`` (uncompressed, deterministic bytes) plus a ``__meta__`` checksum entry,
    written atomically. ``format_name`` / ``format_version`` are recorded in ``__meta__``."""
    if META_KEY in arrays:
        raise ValueError(f"array name {META_KEY!r} is reserved for the checksum entry")
    arrays = {k: np.asanyarray(v) for k, v in arrays.items()}
    meta = {"checksum": "sha256", "sha256": array_digest(arrays), "arrays": sorted(arrays)}
    if format_name is not None:
        meta["format"] = format_name
    if format_version is not None:
        meta["version"] = int(format_version)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays, **{META_KEY: np.array(json.dumps(meta, sort_keys=True))})


def read_npz(path: str | os.PathLike, what: str) -> dict[str, np.ndarray]:
    """All arrays of the ``.npz`` at ``path``, ``__meta__`` included and NOT yet verified (see
    :func:`verify_npz`); any decoding failure raises a TableFileError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise TableFileError(f"{what} {path}: file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files"):
                raise ValueError("a single .npy array, not an .npz archive")
            return {k: z[k] for k in z.files}
    except MemoryError:
        raise TableFileError(f"{what} {path}: unreadable .npz (an array header asks for more "
                             f"memory than available; corrupt file?)") from None
    except Exception as exc:  # noqa: BLE001 - any decoding failure of a corrupt file
        raise TableFileError(f"{what} {path}: unreadable .npz ({type(exc).__name__}: {exc})"
                             ) from None


def decode_json_object(raw: np.ndarray) -> dict | None:
    """The JSON object held by the text scalar ``raw`` (an ``.npz`` entry), or ``None`` when it
    is not one (another dtype or shape, invalid JSON, or JSON other than an object)."""
    if raw.dtype.kind != "U" or raw.shape != ():
        return None
    try:
        obj = json.loads(str(raw))
    except ValueError:
        return None
    return obj if isinstance(obj, dict) else None


def verify_npz(path: str | os.PathLike, what: str, data: dict[str, np.ndarray], *,
               format_name: str | None = None,
               format_version: int | None = None) -> dict[str, np.ndarray]:
    """``data`` (from :func:`read_npz`) without ``__meta__``, after checking it.

    A present ``__meta__`` must be a JSON object whose ``sha256`` matches the other arrays and,
    when given, whose ``format`` and ``version`` match; files without it (written before
    checksums existed) pass unchecked.
    """
    data = dict(data)
    raw = data.pop(META_KEY, None)
    if raw is None:
        return data
    field = f"{what} {path}: {META_KEY}"
    meta = decode_json_object(raw)
    if meta is None:
        raise TableFileError(f"{field}: expected a JSON object string, got "
                             f"{raw.dtype} array of shape {raw.shape}")
    if meta.get("checksum") != "sha256" or not isinstance(meta.get("sha256"), str):
        raise TableFileError(f"{field}.checksum: expected 'sha256' with a 'sha256' digest, got "
                             f"{meta.get('checksum')!r}")
    if sorted(data) != meta.get("arrays"):
        raise TableFileError(f"{field}.arrays: expected {meta.get('arrays')}, found "
                             f"{sorted(data)}")
    digest = array_digest(data)
    if digest != meta["sha256"]:
        raise TableFileError(f"{field}.sha256: checksum mismatch (expected {meta['sha256']}, "
                             f"found {digest}): the file is corrupt or was modified")
    if format_name is not None and meta.get("format", format_name) != format_name:
        raise TableFileError(f"{field}.format: expected {format_name!r}, got "
                             f"{meta.get('format')!r}")
    if format_version is not None and meta.get("version", format_version) != format_version:
        raise TableFileError(f"{field}.version: expected {format_version}, got "
                             f"{meta.get('version')!r}")
    return data


def load_npz_checked(path: str | os.PathLike, what: str, *, format_name: str | None = None,
                     format_version: int | None = None) -> dict[str, np.ndarray]:
    """All arrays of the ``.npz`` at ``path`` (without ``__meta__``), checksum verified.

    ``what`` names the kind of file in messages (e.g. ``"LTC table"``). See :func:`read_npz`
    and :func:`verify_npz`; every failure raises :class:`~prefilter.errors.TableFileError`
    naming the file.
    """
    return verify_npz(path, what, read_npz(path, what), format_name=format_name,
                      format_version=format_version)


def expect_array(data: Mapping[str, np.ndarray], key: str, where: str, *, kind: str = "f",
                 shape: tuple | None = None, ndim: int | None = None,
                 finite: bool = True) -> np.ndarray:
    """``data[key]`` checked for presence, dtype kind (``"f"`` floats, ``"i"`` integers, ``"U"``
    text), shape or number of dimensions and finiteness; else a TableFileError at ``where``."""
    if key not in data:
        raise TableFileError(f"{where}: {key}: missing array")
    a = data[key]
    kinds = {"f": "f", "i": "iu", "U": "U"}[kind]
    if a.dtype.kind not in kinds:
        name = {"f": "floats", "i": "integers", "U": "a text string"}[kind]
        raise TableFileError(f"{where}: {key}: expected {name}, got dtype {a.dtype}")
    if shape is not None and a.shape != tuple(shape):
        raise TableFileError(f"{where}: {key}: expected shape {tuple(shape)}, got {a.shape}")
    if ndim is not None and a.ndim != ndim:
        raise TableFileError(f"{where}: {key}: expected {ndim} dimensions, got shape {a.shape}")
    if finite and kind == "f" and not np.all(np.isfinite(a)):
        raise TableFileError(f"{where}: {key}: expected finite values, got NaN or inf")
    return a


def expect_table_header(data: Mapping[str, np.ndarray], need, where: str, version: int) -> None:
    """The arrays ``need`` are all present and ``data["version"]`` is the integer ``version``;
    else a TableFileError at ``where`` (the shared head of the table loaders)."""
    missing = [k for k in need if k not in data]
    if missing:
        raise TableFileError(f"{where}: missing arrays {missing}; expected {list(need)}")
    v = expect_array(data, "version", where, kind="i", shape=())
    if int(v) != version:
        raise TableFileError(f"{where}: version: expected {version}, got {int(v)}")


def expect_json_object(data: Mapping[str, np.ndarray], key: str, where: str) -> dict:
    """``data[key]``, a text scalar holding a JSON object, decoded; else a TableFileError."""
    expect_array(data, key, where, kind="U", shape=())
    obj = decode_json_object(data[key])
    if obj is None:
        raise TableFileError(f"{where}: {key}: expected a JSON object string")
    return obj


def save_json_atomic(path: str | os.PathLike, obj) -> None:
    with atomic_path(path, suffix=".json") as tmp:
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n")


class Checkpoints:
    """Per-chunk results of a bake, stored beside its output in ``<out>.parts/``.

    ``key`` identifies the bake's settings: parts written under other settings are discarded.
    """

    def __init__(self, out: str | os.PathLike, key: dict):
        self.out = Path(out)
        self.dir = Path(str(out) + ".parts")
        self.key = json.dumps(key, sort_keys=True)
        meta = self.dir / "settings.json"
        if self.dir.exists():
            try:
                same = meta.read_text() == self.key
            except (OSError, ValueError):  # missing, or damaged (not UTF-8)
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
        """Whether chunk ``chunk`` is saved and intact; a damaged part (checksum) is removed so
        the bake recomputes it."""
        f = self._file(chunk)
        if not f.exists():
            return False
        try:
            load_npz_checked(f, "checkpoint")
        except TableFileError:
            f.unlink(missing_ok=True)
            return False
        return True

    def save(self, chunk: int, **arrays: np.ndarray) -> None:
        save_npz_atomic(self._file(chunk), **arrays)

    def load(self, chunk: int) -> dict[str, np.ndarray]:
        """The arrays of a finished chunk (checksum verified)."""
        return load_npz_checked(self._file(chunk), "checkpoint")

    def clear(self) -> None:
        """Remove the parts, and temporary files of :func:`atomic_path` that a bake killed while
        writing its output left beside it (``.<out name>.*``)."""
        shutil.rmtree(self.dir, ignore_errors=True)
        for stale in self.out.parent.glob(f".{glob.escape(self.out.name)}.*"):
            stale.unlink(missing_ok=True)
