"""Numba configuration shared by the hot kernels.

Kernels are compiled with ``parallel=True`` and ``cache=True`` and with LLVM's fast-math flags
as the developers' brief asks, except ``nnan`` and ``ninf`` (:data:`FASTMATH`).
Thread count follows ``NUMBA_NUM_THREADS``; results do not depend on it because every kernel writes
each output element from exactly one iteration (no parallel reductions).

Numba's on-disk cache is keyed by the function's bytecode and signature, not by these flags: after
changing them, delete the ``__pycache__/*.nbi`` / ``*.nbc`` files of the modules with kernels.
"""

from __future__ import annotations

import types

import numba

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

njit_parallel = numba.njit(parallel=True, fastmath=FASTMATH, cache=True)
njit_serial = numba.njit(fastmath=FASTMATH, cache=True)
#: for helpers called from the hot kernels: inlined at the Numba IR level (a call measured ~15 %
#: of the shader's time when left to LLVM)
njit_inline = numba.njit(fastmath=FASTMATH, cache=True, inline="always")
prange = numba.prange


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
    with ``prange`` as ``range``, hence the same results) below :data:`SERIAL_BELOW`."""
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
