"""The shared Numba flags keep IEEE NaN and inf (``fastmath=True`` folds the checks away, so a
NaN guard or an ``inf`` sentinel in a kernel would silently do nothing); the kernel cache lives
in a directory named by the kernel sources' fingerprint."""

from __future__ import annotations

import math
from pathlib import Path

import numba
import numpy as np
import pytest

from prefilter.jit import SERIAL_BELOW, njit_parallel, njit_serial, prange, serial


@njit_serial
def _checks(x):
    return math.isnan(x), math.isinf(x), x != x, not x > 0.0


@njit_serial
def _nearest(ts):
    best = np.inf
    for t in ts:
        if t > 0.0 and t < best:
            best = t
    return best == np.inf, best


@njit_parallel
def _nan_to_zero(a, out):
    for i in prange(a.shape[0]):
        out[i] = 0.0 if math.isnan(a[i]) else a[i]


def test_nan_and_inf_checks_survive_in_kernels():
    assert _checks(np.nan) == (True, False, True, True)
    assert _checks(np.inf) == (False, True, False, False)
    assert _checks(1.0) == (False, False, False, False)
    assert _nearest(np.array([-1.0, -2.0])) == (True, np.inf)
    assert _nearest(np.array([3.0, -2.0, 2.0])) == (False, 2.0)
    a = np.array([1.0, np.nan, -2.0, np.nan])
    for kernel in (_nan_to_zero, serial(_nan_to_zero, 1)):
        out = np.empty(4)
        kernel(a, out)
        assert out.tolist() == [1.0, 0.0, -2.0, 0.0]


def test_fastmath_true_would_fold_them():
    # the reason for the flags: with fastmath=True the same source loses its NaN checks (if a
    # Numba release stops folding them this fails, and the flags could be revisited)
    fast = numba.njit(fastmath=True)(_checks.py_func)
    assert fast(np.nan)[:3] != (True, False, True)


def test_serial_twin_below_threshold():
    assert serial(_nan_to_zero, SERIAL_BELOW) is _nan_to_zero
    twin = serial(_nan_to_zero, SERIAL_BELOW - 1)
    assert twin is not _nan_to_zero and twin is serial(_nan_to_zero, 0)


def _write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_source_fingerprint_follows_kernel_sources_only(tmp_path):
    from prefilter.jit import source_fingerprint

    _write(tmp_path / "a" / "kern.py", "from x import njit_inline\n")
    _write(tmp_path / "b" / "plain.py", "x = 1\n")
    f0 = source_fingerprint(tmp_path)
    _write(tmp_path / "b" / "plain.py", "x = 2\n")  # no kernel: same cache
    assert source_fingerprint(tmp_path) == f0
    _write(tmp_path / "a" / "kern.py", "from x import njit_inline  # edited helper\n")
    f1 = source_fingerprint(tmp_path)
    assert f1 != f0 and len(f1) == 16
    (tmp_path / "a" / "kern.py").rename(tmp_path / "a" / "moved.py")  # the path counts too
    assert source_fingerprint(tmp_path) != f1


def test_cache_dir_environment(monkeypatch, tmp_path):
    from prefilter import jit

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("PREFILTER_NUMBA_CACHE", str(tmp_path))
    d = jit.cache_dir()
    assert d.parent == tmp_path
    assert d.name == jit.source_fingerprint(Path(jit.__file__).parent)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "user"))
    assert jit.cache_dir() is None


def test_kernels_cache_under_the_fingerprint_directory():
    import os

    from prefilter import jit

    if os.environ.get("NUMBA_CACHE_DIR"):
        pytest.skip("NUMBA_CACHE_DIR set by the user: Numba's own rule applies")
    d = Path(numba.config.CACHE_DIR)
    assert d.name == jit.source_fingerprint(Path(jit.__file__).parent)
    from prefilter.sphere import polygon  # noqa: F401  (a module with kernels)

    kernels = [v for v in vars(polygon).values() if hasattr(v, "_cache")]
    assert kernels
    for k in kernels:
        assert Path(k._cache._cache_path).is_relative_to(d)


def test_prune_deletes_only_old_siblings(tmp_path):
    import os
    import time

    from prefilter.jit import CACHE_MAX_AGE_DAYS, _prune

    cur, old, recent = tmp_path / "cur", tmp_path / "old", tmp_path / "recent"
    for d in (cur, old, recent):
        d.mkdir()
    past = time.time() - (CACHE_MAX_AGE_DAYS + 1) * 86400.0
    os.utime(old, (past, past))
    os.utime(cur, (past, past))  # the current one is never deleted
    _prune(cur)
    assert cur.exists() and recent.exists() and not old.exists()


def test_kernel_array_is_contiguous_writable_and_copies_only_when_needed():
    from prefilter.jit import kernel_array

    b = kernel_array(np.arange(3.0), (4, 3))  # broadcast: a writable copy
    assert b.flags.c_contiguous and b.flags.writeable and b.shape == (4, 3)
    ro = np.arange(6.0).reshape(2, 3)
    ro.flags.writeable = False
    assert kernel_array(ro, (2, 3)).flags.writeable
    w = np.arange(6.0).reshape(2, 3)
    assert kernel_array(w, (2, 3)) is w
    assert kernel_array(np.arange(3), (3,), np.float64).dtype == np.float64


def test_broadcast_arguments_do_not_compile_read_only_specializations():
    # np.broadcast_to views are read-only, and Numba compiles read-only arrays separately: the
    # GGX sampler with a scalar roughness (broadcast) and with per-point arrays must share one
    from numba import types as nbt

    from prefilter.jit import serial
    from prefilter.microfacet import GGX
    from prefilter.microfacet.ggx import _sample_vndf_kernel

    wo = np.array([0.3, 0.1, 0.9]) / np.linalg.norm([0.3, 0.1, 0.9])
    u = np.random.default_rng(0).random((5, 2))
    GGX(0.3).sample_vndf(wo, u)
    GGX(np.full(5, 0.3), np.full(5, 0.2)).sample_vndf(np.tile(wo, (5, 1)), u)
    twin = serial(_sample_vndf_kernel, 5)
    assert twin.signatures
    for sig in twin.signatures:
        assert all(a.mutable for a in sig if isinstance(a, nbt.Array)), sig
