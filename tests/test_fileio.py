"""``prefilter.fileio``: checksummed ``.npz``, output locks and file sets switched as one unit."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from prefilter.errors import PrefilterError, TableFileError
from prefilter.fileio import (META_KEY, atomic_file_set, bake_lock, exclusive_lock,
                              load_npz_checked, lock_path, save_npz_atomic, user_data_dir)


def test_npz_without_meta_is_refused(tmp_path):
    """Deleting ``__meta__`` must not switch the checksum off: the file is refused, naming it."""
    p = tmp_path / "t.npz"
    save_npz_atomic(p, a=np.arange(3.0))
    with np.load(p) as z:
        arrays = {k: z[k] for k in z.files if k != META_KEY}
    arrays["a"] = arrays["a"] + 1.0  # an edit the checksum would have caught
    np.savez(p, **arrays)
    with pytest.raises(TableFileError, match=r"t\.npz: __meta__: expected the checksum entry"):
        load_npz_checked(p, "table")


def test_shipped_tables_carry_checksums():
    from prefilter.ltc.aniso.table import AnisoGGXTable
    from prefilter.ltc.aniso.table import shipped_table_path as aniso_path
    from prefilter.ltc.fit_iso import shipped_table_path
    from prefilter.ltc.table import GGXTable

    for path, cls in ((shipped_table_path(), GGXTable), (aniso_path(), AnisoGGXTable)):
        with np.load(path) as z:
            assert META_KEY in z.files
        assert cls.load(path).source == "shipped"


def _hold(path, *, seconds: float = 30.0) -> subprocess.Popen:
    """A process holding ``bake_lock(path)`` (prints ``locked`` once it holds it)."""
    proc = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time; from prefilter.fileio import bake_lock\n"
         "with bake_lock(sys.argv[1]):\n"
         "    print('locked', flush=True); time.sleep(float(sys.argv[2]))",
         str(path), str(seconds)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_bake_lock_fails_at_once_naming_the_holder(tmp_path):
    out = tmp_path / "x.npz"
    holder = _hold(out)
    try:
        with pytest.raises(PrefilterError) as err:
            with bake_lock(out):
                pass
        msg = str(err.value)
        assert f"pid {holder.pid}" in msg and "bake_lock" in msg and "started" in msg
        assert "--wait" in msg and "\n" not in msg
    finally:
        holder.kill()
        holder.wait()
    with bake_lock(out):  # the lock of a killed holder is free
        assert lock_path(out).exists()
    assert not lock_path(out).exists()


def test_bake_lock_waits_when_asked(tmp_path):
    out = tmp_path / "x.npz"
    holder = _hold(out, seconds=1.0)
    t0 = time.monotonic()
    with bake_lock(out, wait=True):
        assert time.monotonic() - t0 > 0.5  # entered only once the holder had released it
    holder.wait()


def test_bake_lock_reenters_in_a_thread_and_excludes_other_threads(tmp_path):
    out = tmp_path / "x.npz"
    seen = []
    with bake_lock(out):
        with bake_lock(out):  # the CLI locks, then the library bake: no self-deadlock
            pass

        def other():
            try:
                with bake_lock(out):
                    seen.append("entered")
            except PrefilterError:
                seen.append("refused")

        t = threading.Thread(target=other)
        t.start()
        t.join()
        assert lock_path(out).exists()
    assert seen == ["refused"]
    with exclusive_lock(lock_path(out)):
        pass


def _write_set(paths, a: bytes, b: bytes, fail: bool = False):
    with atomic_file_set(paths) as (pa, pb):
        pa.write_bytes(a)
        if fail:
            raise RuntimeError("killed between the two files")
        pb.write_bytes(b)


def test_file_set_switches_as_one_unit(tmp_path):
    paths = [tmp_path / "t.png", tmp_path / "t.json"]
    for p, data in zip(paths, (b"old table", b"old meta")):  # a pair written by plain writes
        p.write_bytes(data)
    _write_set(paths, b"v1", b"m1")
    assert [p.read_bytes() for p in paths] == [b"v1", b"m1"]
    with pytest.raises(RuntimeError):
        _write_set(paths, b"v2", b"m2", fail=True)
    assert [p.read_bytes() for p in paths] == [b"v1", b"m1"]
    # readers resolve the first file and read the rest beside it: one version, always
    real = paths[0].resolve()
    assert real.with_suffix(".json").read_bytes() == b"m1"
    for i in range(3):
        _write_set(paths, b"v%d" % (i + 3), b"m%d" % (i + 3))
    assert [p.read_bytes() for p in paths] == [b"v5", b"m5"]
    versions = [d for d in (tmp_path / ".t.png-versions").iterdir() if d.name != "current"]
    assert len(versions) == 2  # the current one and the one before, for slow readers
    assert sorted(p.name for p in tmp_path.iterdir()) == [".t.png-versions", "t.json", "t.png"]


def test_user_data_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("PREFILTER_DATA", str(tmp_path / "d"))
    assert user_data_dir() == tmp_path / "d"
    monkeypatch.delenv("PREFILTER_DATA")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "x"))
    assert user_data_dir() == tmp_path / "x" / "prefilter"
    monkeypatch.delenv("XDG_DATA_HOME")
    assert str(user_data_dir()) == os.path.expanduser("~/.local/share/prefilter")
