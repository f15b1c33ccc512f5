"""Numba configuration shared by the hot kernels.

Kernels are compiled with ``parallel=True, fastmath=True, cache=True`` as the developers' brief asks.
Thread count follows ``NUMBA_NUM_THREADS``; results do not depend on it because every kernel writes
each output element from exactly one iteration (no parallel reductions).
"""

from __future__ import annotations

import numba

njit_parallel = numba.njit(parallel=True, fastmath=True, cache=True)
njit_serial = numba.njit(fastmath=True, cache=True)
prange = numba.prange
