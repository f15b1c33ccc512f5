"""The shared Numba flags keep IEEE NaN and inf (``fastmath=True`` folds the checks away, so a
NaN guard or an ``inf`` sentinel in a kernel would silently do nothing)."""

from __future__ import annotations

import math

import numba
import numpy as np

from prefilter._numba import SERIAL_BELOW, njit_parallel, njit_serial, prange, serial


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
