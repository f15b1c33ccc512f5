"""Atomic writes, checksummed files and chunk checkpoints for long bakes.

A bake writes each finished chunk to ``<out>.parts/<chunk>.npz`` (atomically), so a killed bake
restarts from the last finished chunk; the final output is written to a temporary file in the same
directory and renamed over the target, so readers never see a half-written file.

Every ``.npz`` written by :func:`save_npz_atomic` carries a ``__meta__`` entry, a JSON string
``{"checksum": "sha256", "sha256": ..., "arrays": [...], "format": ..., "version": ...}`` whose
digest (:func:`array_digest`) covers the names, dtypes, shapes and bytes of all other arrays.
:func:`load_npz_checked` verifies it (a file without ``__meta__`` is refused: removing the entry
must not turn the checksum off) and turns every decoding failure into a
:class:`~prefilter.errors.TableFileError` that names the file.

A bake holds :func:`bake_lock` on its output for its whole run: a second bake of the same output
fails at once naming the holder (or waits, ``wait=True``). Files that only make sense together
(a table and its sidecar) are written by :func:`atomic_file_set`, which switches all of them to
the new version with one atomic rename. :func:`user_data_dir` is where bakes write tables that
replace the package's own.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import shlex
import shutil
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Mapping, Sequence

import numpy as np

from prefilter.errors import PrefilterError, TableFileError

#: Name of the checksum entry of a ``.npz`` written by :func:`save_npz_atomic`.
META_KEY = "__meta__"


#: Lock files held by this process: (resolved path, thread) -> [file descriptor, depth]. A bake
#: that calls another locked bake on the same output in the same thread (the CLI locks, then the
#: library bake locks again) re-enters the lock instead of waiting for itself; another thread
#: waits as another process does.
_HELD: dict[tuple[str, int], list[int]] = {}
_HELD_GUARD = threading.Lock()


def _holder_text() -> str:
    """What a lock file records about its holder: pid, command line and start time (JSON)."""
    return json.dumps({"pid": os.getpid(), "command": shlex.join(sys.argv),
                       "started": time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime())})


def _describe_holder(fd: int) -> str:
    """The holder recorded in the lock file open as ``fd`` ("pid P, command C, started T")."""
    info = None
    for _ in range(20):  # the holder writes its record right after locking: give it a moment
        try:
            info = json.loads(os.pread(fd, 1 << 16, 0).decode("utf-8", "replace"))
            break
        except (OSError, ValueError):
            time.sleep(0.025)
    if not isinstance(info, dict):
        return "a process that has not recorded itself yet"
    return (f"pid {info.get('pid', '?')}, command {info.get('command', '?')!r}, "
            f"started {info.get('started', '?')}")


@contextmanager
def exclusive_lock(path: str | os.PathLike, *, wait: bool = True,
                   what: str | None = None) -> Iterator[None]:
    """Hold an exclusive advisory lock on the file ``path`` (created if missing) for the block.

    ``wait=True`` blocks until the holder leaves; ``wait=False`` raises
    :class:`~prefilter.errors.PrefilterError` at once, naming ``what`` (default: ``path``) and
    the holder: its pid, command line and start time, which the holder writes into the lock
    file. Re-entrant within a process. The lock file is unlinked on release; a waiter that then
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
    key = (str(path.resolve()), threading.get_ident())
    with _HELD_GUARD:
        held = _HELD.get(key)
        if held is not None:
            held[1] += 1
    if held is not None:
        try:
            yield
        finally:
            with _HELD_GUARD:
                held[1] -= 1
        return
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
            except BlockingIOError:
                raise PrefilterError(
                    f"{what or path}: expected no other bake writing this output, got one "
                    f"running ({_describe_holder(fd)}); wait for it to finish, or pass --wait "
                    f"to queue behind it") from None
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
        os.ftruncate(fd, 0)
        os.pwrite(fd, _holder_text().encode(), 0)
    except OSError:
        pass  # the record only improves the message a contender prints
    with _HELD_GUARD:
        _HELD[key] = [fd, 1]
    try:
        yield
    finally:
        with _HELD_GUARD:
            del _HELD[key]
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
        os.close(fd)


def lock_path(out: str | os.PathLike) -> Path:
    """The lock file of the output ``out`` of a bake: ``<out>.lock``."""
    return Path(str(out) + ".lock")


def bake_lock(out: str | os.PathLike, *, wait: bool = False):
    """:func:`exclusive_lock` on :func:`lock_path` ``(out)``, held by a bake of ``out`` for its
    whole run (checkpoints, final write, clean-up), so that two bakes of one output never mix
    rows or delete each other's parts. ``wait=False``: a second bake fails at once (a
    :class:`~prefilter.errors.PrefilterError` naming the holder); ``wait=True``: it waits."""
    return exclusive_lock(lock_path(out), wait=wait, what=out)


def user_data_dir() -> Path:
    """Where bakes write tables that take the place of the package's own: ``$PREFILTER_DATA``,
    else ``$XDG_DATA_HOME/prefilter``, else ``~/.local/share/prefilter``."""
    base = os.environ.get("PREFILTER_DATA")
    if base:
        return Path(base).expanduser()
    xdg = os.environ.get("XDG_DATA_HOME")
    return (Path(xdg) if xdg else Path.home() / ".local" / "share") / "prefilter"


def table_source(path: str | os.PathLike, shipped: str | os.PathLike) -> str:
    """Where a table file comes from: ``"shipped"`` (the package's own, ``shipped``), ``"user"``
    (in :func:`user_data_dir`) or ``"file"`` (any other path)."""
    path = Path(path).resolve()
    if path == Path(shipped).resolve():
        return "shipped"
    return "user" if path.parent == user_data_dir().resolve() else "file"


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
    os.chmod(tmp, 0o666 & ~_umask())
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

    ``__meta__`` must be present, a JSON object whose ``sha256`` matches the other arrays and,
    when given, whose ``format`` and ``version`` match. A file without it is refused: the
    project's own formats are always written with it, and deleting the entry must not be a way
    to skip the check.
    """
    data = dict(data)
    raw = data.pop(META_KEY, None)
    field = f"{what} {path}: {META_KEY}"
    if raw is None:
        raise TableFileError(f"{field}: expected the checksum entry, got none: the file was "
                             f"edited or not written by prefilter; re-bake it")
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
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_path`); returns ``Path(path)``."""
    path = Path(path)
    with atomic_path(path, suffix="".join(path.suffixes) or ".txt") as tmp:
        tmp.write_text(text)
    return path


#: Folder beside a file set's first file holding its versions (see :func:`atomic_file_set`).
VERSIONS_SUFFIX = "-versions"


def _symlink_over(target: str, link: Path) -> None:
    """Make ``link`` a symbolic link to ``target`` with one atomic rename (over any file)."""
    tmp = link.parent / f".{link.name}.{os.getpid()}-{threading.get_ident()}.link"
    tmp.unlink(missing_ok=True)
    os.symlink(target, tmp)
    os.replace(tmp, link)


def _fsync_dir(d: Path) -> None:
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory descriptors
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_file_set(paths: Sequence[str | os.PathLike]) -> Iterator[list[Path]]:
    """Write files that belong together (a table and its sidecar) as one unit.

    Yields one path per entry of ``paths`` (same folder, distinct names) inside a new version
    folder ``.<first name>-versions/<token>/``; when the block succeeds, the version becomes
    current with one atomic rename of the link ``.<first name>-versions/current``, and each of
    ``paths`` is (made) a relative symbolic link to ``current/<name>``. A process killed at any
    moment leaves the previous set or the new one, never a mix; the previous version is kept
    for readers that resolved its links just before the switch, older ones are removed.
    Readers should resolve the first path (``Path.resolve``) and read the others next to it.
    Without symbolic links (some Windows set-ups) the files are replaced one by one.
    """
    paths = [Path(p) for p in paths]
    folder = paths[0].parent
    if any(p.parent != folder for p in paths) or len({p.name for p in paths}) != len(paths):
        raise ValueError("atomic_file_set: expected distinct names in one folder")
    folder.mkdir(parents=True, exist_ok=True)
    store = folder / f".{paths[0].name}{VERSIONS_SUFFIX}"
    store.mkdir(exist_ok=True)
    version = Path(tempfile.mkdtemp(prefix="v", dir=store))
    os.chmod(version, 0o777 & ~_umask())
    try:
        yield [version / p.name for p in paths]
        for p in paths:
            if not (version / p.name).is_file():
                raise FileNotFoundError(f"{version / p.name}: not written")
            with open(version / p.name, "rb") as fh:
                os.fsync(fh.fileno())
        _fsync_dir(version)
        current = store / "current"
        try:
            previous = os.readlink(current)
        except OSError:
            previous = None
        try:
            _symlink_over(version.name, current)
        except (OSError, NotImplementedError):  # pragma: no cover - no symbolic links
            for p in paths:
                os.replace(version / p.name, p)
            shutil.rmtree(store, ignore_errors=True)
            return
        _fsync_dir(store)
        for p in paths:
            target = f"{store.name}/current/{p.name}"
            if not (p.is_symlink() and os.readlink(p) == target):
                _symlink_over(target, p)
        _fsync_dir(folder)
        for old in store.iterdir():
            if old.name not in (version.name, previous, "current"):
                if old.is_dir() and not old.is_symlink():
                    shutil.rmtree(old, ignore_errors=True)
                else:
                    old.unlink(missing_ok=True)
    except BaseException:
        shutil.rmtree(version, ignore_errors=True)
        raise


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


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
            if stale.is_file():
                stale.unlink(missing_ok=True)
