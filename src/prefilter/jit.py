"""Numba configuration shared by the hot kernels.

Kernels are compiled with ``parallel=True`` and ``cache=True`` and with LLVM's fast-math flags
as the developers' brief asks, except ``nnan`` and ``ninf`` (:data:`FASTMATH`).
Thread count follows ``NUMBA_NUM_THREADS``; results do not depend on it because every kernel writes
each output element from exactly one iteration (no parallel reductions).

Numba's on-disk cache is keyed by the function's bytecode and signature, not by these flags: after
changing them, delete the cache directory (:func:`cache_dir`).

Numba invalidates a cached kernel when *its own* source file changes, but the kernels inline
helpers from other modules (``njit_inline``): after editing such a helper, kernels of other
modules kept running the old one from their cache. So the cache lives in a directory named by a
fingerprint of every kernel source of the package (:func:`cache_dir`); any edit starts a fresh
one (compilation is lazy: only the kernels a process calls are recompiled).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import time
import types
from pathlib import Path

import numba
import numpy as np

#: LLVM fast-math flags of every kernel: those of ``fastmath=True`` but ``nnan`` and ``ninf``.
#: With those two LLVM may assume that no value is NaN or infinite, and it does:
#: ``math.isnan(x)``, ``math.isinf(x)`` and ``x != x`` compile to ``False``, and an ``inf``
#: sentinel compared after a search (``best == np.inf``: "no hit") folds to ``False`` (see
#: tests/test_numba.py). Without them NaN and inf keep their IEEE meaning; reassociation,
#: contraction (FMA), reciprocals, signed zeros and fast math functions stay. Measured cost: none
#: above the noise (CPU time, 1 thread, two alternating runs each, with vs without the two flags:
#: 4e5 polygon integrals 43.1/43.6 vs 42.4/40.1 ms, ``ltc`` 256^2 42.0/38.9 vs 38.7/36.1 ms,
#: ``reference`` 64^2 x 16 spp 80.0/76.1 vs 73.4/70.5 ms).
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

#: Fingerprint directories of the Numba cache unused for this long are deleted at import.
CACHE_MAX_AGE_DAYS = 14


def source_fingerprint(root: str | os.PathLike) -> str:
    """16 hex digits of SHA-1 over the relative paths and bytes of the ``.py`` files under
    ``root`` that define Numba kernels (those mentioning ``njit``), in sorted order."""
    root = Path(root)
    h = hashlib.sha1()
    for f in sorted(root.rglob("*.py")):
        data = f.read_bytes()
        if b"njit" in data:
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + data)
    return h.hexdigest()[:16]


def cache_dir() -> Path | None:
    """Where the kernels' compiled code is cached: ``$PREFILTER_NUMBA_CACHE`` (default
    ``$XDG_CACHE_HOME/prefilter/numba`` or ``~/.cache/prefilter/numba``) / the package's
    :func:`source_fingerprint`; ``None`` when the user set ``NUMBA_CACHE_DIR`` (then Numba's
    own rule applies)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    base = os.environ.get("PREFILTER_NUMBA_CACHE")
    if not base:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = Path(xdg) / "prefilter" / "numba" if xdg else \
            Path.home() / ".cache" / "prefilter" / "numba"
    return Path(base) / source_fingerprint(Path(__file__).parent)


def _prune(current: Path) -> None:
    """Delete sibling fingerprint directories unused for :data:`CACHE_MAX_AGE_DAYS`."""
    cutoff = time.time() - CACHE_MAX_AGE_DAYS * 86400.0
    for d in current.parent.iterdir():
        try:
            if d != current and d.is_dir() and d.stat().st_mtime < cutoff:
                shutil.rmtree(d, ignore_errors=True)
        except OSError:
            pass


def _use_cache_dir() -> None:
    # must run before any kernel is decorated: Numba fixes a kernel's cache path then
    d = cache_dir()
    if d is None:
        return
    try:
        d.mkdir(parents=True, exist_ok=True)
        os.utime(d)  # marks it used, for _prune
    except OSError:
        return  # unwritable: Numba's default (__pycache__ next to the sources)
    numba.config.CACHE_DIR = str(d)
    _prune(d)


_use_cache_dir()

njit_parallel = numba.njit(parallel=True, fastmath=FASTMATH, cache=True)
njit_serial = numba.njit(fastmath=FASTMATH, cache=True)
#: for helpers called from the hot kernels: inlined at the Numba IR level (a call measured ~15 %
#: of the shader's time when left to LLVM)
njit_inline = numba.njit(fastmath=FASTMATH, cache=True, inline="always")
prange = numba.prange


def release_heap() -> None:
    """Return the C heap's free pages to the system (glibc's ``malloc_trim``; nothing where there
    is none). Threads (the kernels', a bake's pool) allocate in glibc arenas of their own whose
    freed pages stay resident: a glints bake of a 256^2 map left the process at 772 MiB, 243 MiB
    after this; the docs example's cold glints render (two bakes, then the render) peaked at
    1747 MiB instead of 1999 MiB (``benchmarks/bench_glints_cold.py``)."""
    try:
        trim = ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return
    trim(0)


def kernel_array(a, shape, dtype=None):
    """``a`` broadcast to ``shape`` as a C-contiguous, writable array (of ``dtype``, default its
    own), to pass to a kernel. Numba compiles a separate specialization for read-only arrays, and
    ``np.broadcast_to`` views are read-only: without this a kernel compiled twice, depending on
    whether an argument needed broadcasting. Copies only when ``a`` is read-only, broadcast,
    non-contiguous or of another dtype."""
    a = np.asarray(a, dtype=dtype)
    if a.shape != tuple(shape):
        a = np.broadcast_to(a, shape)
    return np.require(a, a.dtype, ["C", "W"])


#: Batches smaller than this run a serial twin of a parallel kernel: waking the thread pool costs
#: more than the work. Measured (median wall time per call, batch sizes 2^6..2^18) on the 2-core
#: development machine under load (~20 runnable threads): with 2 threads the parallel kernel pays
#: ~20 ms (a scheduler time slice) at any size and only ties with its serial twin at 65536 polygon
#: integrals (19 ms serial) or 65536 LTC shading points (108 ms); with 1 thread both are equal at
#: every size (within 10 %). On a quiet machine the parallel kernel wins from a few thousand
#: items. 2^15 is where the serial work is about that wake-up cost (polygon integrals 7-11 ms, LTC
#: shading 54 ms): the time lost is a few tens of ms per call at most, loaded or quiet.
SERIAL_BELOW = 1 << 15

_SERIAL: dict = {}


def serial(kernel, n: int):
    """``kernel`` for a batch of ``n`` items: its serial twin (the same Python source compiled
    with ``prange`` as ``range``: the same results up to fastmath reassociation of float32
    sums, seen at 1e-7 relative; the choice depends only on ``n``, so a command stays
    deterministic) below :data:`SERIAL_BELOW`."""
    if n >= SERIAL_BELOW:
        return kernel
    twin = _SERIAL.get(kernel)
    if twin is None:
        # Numba's on-disk cache is keyed by qualified name and signature, not by the parallel
        # flag: a twin of the same function would overwrite (and be loaded as) the parallel one.
        f = kernel.py_func
        g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__,
                               f.__closure__)
        g.__qualname__ = f.__qualname__ + "_serial"
        g.__doc__ = f.__doc__
        twin = _SERIAL[kernel] = njit_serial(g)
    return twin
