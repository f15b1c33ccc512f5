"""Numba configuration shared by the hot kernels.

Kernels are compiled with ``parallel=True, fastmath=True, cache=True`` as the developers' brief
asks.
Thread count follows ``NUMBA_NUM_THREADS``; results do not depend on it because every kernel writes
each output element from exactly one iteration (no parallel reductions).
"""

from __future__ import annotations

import types

import numba

njit_parallel = numba.njit(parallel=True, fastmath=True, cache=True)
njit_serial = numba.njit(fastmath=True, cache=True)
#: for helpers called from the hot kernels: inlined at the Numba IR level (a call measured ~15 %
#: of the shader's time when left to LLVM)
njit_inline = numba.njit(fastmath=True, cache=True, inline="always")
prange = numba.prange


#: Batches smaller than this run a serial twin of a parallel kernel: waking the thread pool costs
#: more than the work (measured: 4.7 ms vs 0.1 ms for 128 polygon integrals on 2 cores).
SERIAL_BELOW = 2048

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
