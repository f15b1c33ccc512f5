"""Input validation helpers used at public API boundaries.

Each helper returns a clean float64 array or raises :class:`~prefilter.errors.PrefilterError` whose
message says which parameter was wrong, what it was and what was expected.
"""

from __future__ import annotations

import os

import numpy as np

from prefilter.errors import PrefilterError


def _describe(x: np.ndarray) -> str:
    if x.size <= 6:
        return f"{np.array2string(np.asarray(x), precision=4)}"
    return f"array of shape {x.shape}"


def as_float_array(x, name: str, *, ndim_min: int = 0, last_dim: int | None = None) -> np.ndarray:
    """``x`` as a finite float64 array, checking its trailing dimension.

    Booleans, integers and floats are accepted; strings, bytes, complex numbers, ``None`` and
    ragged lists are not (NumPy would parse ``"0.5"``, drop imaginary parts and turn ``None``
    into NaN).
    """
    try:
        raw = x if isinstance(x, np.ndarray) else np.asarray(x)
    except (TypeError, ValueError):  # ragged nested sequences
        raise PrefilterError(f"{name}: expected a numeric array, got {type(x).__name__}") from None
    kind = raw.dtype.kind
    if kind not in "biuf" and not (kind == "O" and all(
            isinstance(v, (int, float, np.integer, np.floating)) for v in raw.flat)):
        what = type(x).__name__ if kind == "O" or raw.ndim == 0 else f"dtype {raw.dtype}"
        raise PrefilterError(f"{name}: expected a numeric array, got {what}")
    try:
        a = raw.astype(np.float64, copy=False)
    except OverflowError:  # Python integers beyond the float range
        raise PrefilterError(f"{name}: expected finite values, got an integer too large for a "
                             "float") from None
    if a.ndim < ndim_min:
        raise PrefilterError(f"{name}: expected at least {ndim_min} dimensions, "
                             f"got shape {a.shape}")
    if last_dim is not None and (a.ndim == 0 or a.shape[-1] != last_dim):
        raise PrefilterError(f"{name}: expected shape (..., {last_dim}), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise PrefilterError(f"{name}: expected finite values, got NaN or inf in {_describe(a)}")
    return a


def as_directions(w, name: str, *, tol: float = 1e-3, normalize: bool = True) -> np.ndarray:
    """Unit direction vectors ``(..., 3)``.

    Vectors whose length differs from 1 by more than ``tol`` are rejected (a common bug is passing
    un-normalised vectors); those within ``tol`` are renormalised exactly when ``normalize``.
    """
    a = as_float_array(w, name, ndim_min=1, last_dim=3)
    with np.errstate(over="ignore", under="ignore"):
        n = np.linalg.norm(a, axis=-1)
    if not np.all(np.isfinite(n)):  # |w|^2 overflowed: the scaled norm names the true length
        big = np.max(np.abs(a), axis=-1)
        with np.errstate(over="ignore"):
            n = np.where(np.isfinite(n), n, big * np.linalg.norm(
                a / np.where(big > 0, big, 1.0)[..., None], axis=-1))
    bad = np.abs(n - 1.0) > tol
    if np.any(bad):
        raise PrefilterError(
            f"{name}: expected unit vectors (|w| = 1 within {tol}), got lengths "
            f"{_describe(n[bad][:4])}"
        )
    return a / n[..., None] if normalize else a


def as_upper_directions(w, name: str, *, tol: float = 1e-3) -> np.ndarray:
    """Unit directions in the upper hemisphere (``w_z > 0``), e.g. a view direction."""
    a = as_directions(w, name, tol=tol)
    if np.any(a[..., 2] <= 0.0):
        raise PrefilterError(
            f"{name}: expected directions above the surface (z > 0), got z = "
            f"{_describe(a[..., 2][a[..., 2] <= 0][:4])}"
        )
    return a


def as_roughness(alpha, name: str, *, lo: float = 1e-4, hi: float = 4.0) -> np.ndarray:
    """Microfacet roughness values in ``[lo, hi]``."""
    a = as_float_array(alpha, name)
    if np.any((a < lo) | (a > hi)):
        raise PrefilterError(f"{name}: expected roughness in [{lo}, {hi}], got {_describe(a)}")
    return a


def as_uniform(u, name: str, *, last_dim: int) -> np.ndarray:
    """Uniform random numbers in ``[0, 1]`` with trailing dimension ``last_dim``."""
    a = as_float_array(u, name, ndim_min=1, last_dim=last_dim)
    if np.any((a < 0.0) | (a > 1.0)):
        raise PrefilterError(f"{name}: expected numbers in [0, 1], got {_describe(a)}")
    return a


def as_rng(rng, name: str = "rng") -> np.random.Generator:
    """A NumPy Generator; an integer seed ``>= 0`` seeds a fresh one, ``None`` is rejected
    (determinism)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        if int(rng) < 0:  # NumPy's SeedSequence refuses negative entropy with a bare ValueError
            raise PrefilterError(f"{name}: expected an integer seed >= 0, got {int(rng)}")
        return np.random.default_rng(int(rng))
    raise PrefilterError(
        f"{name}: expected a numpy.random.Generator or an integer seed, got {type(rng).__name__}"
    )


def as_positive_int(n, name: str, *, lo: int = 1, hi: int | None = None) -> int:
    """An integer in ``[lo, hi]`` (booleans, floats and strings are not integers)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or int(n) < lo:
        raise PrefilterError(f"{name}: expected an integer >= {lo}, got {_short(n)}")
    if hi is not None and int(n) > hi:
        raise PrefilterError(f"{name}: expected an integer in [{lo}, {hi}], got {_short(n)}")
    return int(n)


def _short(v) -> str:
    """``repr(v)``, or its digit count for integers too long to print in one line."""
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool) and abs(int(v)) >= 10**30:
        return f"an integer of {len(str(abs(int(v))))} digits"
    return repr(v)


def check_scalar(x, name: str, *, lo: float = -np.inf, hi: float = np.inf,
                 lo_open: bool = False, hi_open: bool = False) -> float:
    """One finite real number in the interval from ``lo`` to ``hi`` (closed unless ``lo_open`` /
    ``hi_open``), as a Python float.

    Python and NumPy integers and floats and 0-d numeric arrays are numbers; booleans, strings,
    complex numbers, ``None``, containers and arrays of any other shape are not. Integers beyond
    the float range are refused with the same message as other out-of-range values.
    """
    ok_type = (isinstance(x, (int, float, np.integer, np.floating))
               or (isinstance(x, np.ndarray) and x.ndim == 0 and x.dtype.kind in "iuf"))
    if isinstance(x, (bool, np.bool_)) or not ok_type:
        what = f"array of shape {x.shape}" if isinstance(x, np.ndarray) else type(x).__name__
        raise PrefilterError(f"{name}: expected a number, got {what}")
    try:
        v = float(x)
    except OverflowError:  # a Python integer beyond 1.8e308
        v = float("inf") if x > 0 else float("-inf")
    inside = (lo < v if lo_open else lo <= v) and (v < hi if hi_open else v <= hi)
    if not (np.isfinite(v) and inside):
        if (lo, hi) == (-np.inf, np.inf):
            want = "a finite number"
        elif hi == np.inf:
            want = f"a number {'>' if lo_open else '>='} {lo:g}"
        elif lo == -np.inf:
            want = f"a number {'<' if hi_open else '<='} {hi:g}"
        else:
            want = (f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}"
                    f"{')' if hi_open else ']'}")
        raise PrefilterError(f"{name}: expected {want}, got {_short(x)}")
    return v


#: Largest slope magnitude (mean slopes, square root of slope variances) accepted by the slope
#: statistics: a normal 1e-6 rad from the horizon. Beyond it the grid integrators' Jacobians and
#: determinants leave the float range.
SLOPE_MAX = 1e6


def as_slope_covariance(cov, name: str, *, max_variance: float = SLOPE_MAX ** 2) -> np.ndarray:
    """Symmetric positive definite 2x2 slope covariances ``(..., 2, 2)`` with variances at most
    ``max_variance`` (default :data:`SLOPE_MAX` squared), so that the determinant is finite.

    Symmetry is checked relative to the variances (1e-9); definiteness by the determinant
    ``s_xx s_yy - s_xy^2 > 0`` with both variances positive.
    """
    c = as_float_array(cov, name, ndim_min=2)
    if c.shape[-2:] != (2, 2):
        raise PrefilterError(f"{name}: expected shape (..., 2, 2), got {c.shape}")
    sxx, syy, sxy = c[..., 0, 0], c[..., 1, 1], c[..., 0, 1]
    big = np.abs(c) > max_variance
    if np.any(big):
        raise PrefilterError(f"{name}: expected entries of magnitude <= {max_variance:g}, got "
                             f"{_describe(np.abs(c)[big][:4])}")
    if np.any(np.abs(c[..., 0, 1] - c[..., 1, 0]) > 1e-9 * np.maximum(np.abs(sxx), np.abs(syy))):
        raise PrefilterError(f"{name}: expected symmetric covariances, got different "
                             "off-diagonal entries")
    if np.any(sxx <= 0) or np.any(syy <= 0) or np.any(sxx * syy - sxy * sxy <= 0):
        raise PrefilterError(f"{name}: expected positive definite covariances, got a singular or "
                             "indefinite one")
    return c


# -- memory ----------------------------------------------------------------------------------

#: Environment variable holding the memory budget (bytes, or with a K/M/G/T suffix, powers of 2).
MEMORY_BUDGET_ENV = "PREFILTER_MEMORY_BUDGET"
#: Default budget: this fraction of the machine's physical memory.
MEMORY_FRACTION = 0.5
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40, "P": 1 << 50}


def format_bytes(n: float) -> str:
    """``n`` bytes in binary units (``"7.3 TiB"``)."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024.0:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    return f"{n:.1f} PiB" if n < 1e4 else f"{n:.2e} PiB"


def memory_budget() -> int:
    """The memory budget in bytes: :data:`MEMORY_BUDGET_ENV` if set (``"8G"``, ``"512M"``,
    ``"1000000"``), else :data:`MEMORY_FRACTION` of the physical memory (8 GiB where the system
    does not report it)."""
    raw = os.environ.get(MEMORY_BUDGET_ENV, "").strip()
    if raw:
        text = raw.upper().removesuffix("IB").removesuffix("B")
        unit = text[-1] if text and text[-1] in _UNITS else ""
        try:
            value = float(text[:len(text) - len(unit)])
        except ValueError:
            value = float("nan")
        if not (np.isfinite(value) and value > 0):
            raise PrefilterError(f"{MEMORY_BUDGET_ENV}: expected a positive size in bytes (e.g. "
                                 f"8G, 512M, 1000000), got {raw!r}")
        return int(value * _UNITS[unit])
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX
        total = 16 << 30
    return int(total * MEMORY_FRACTION) if total > 0 else 8 << 30


def check_memory(nbytes, what: str) -> int:
    """``nbytes`` (an estimate of what ``what`` allocates) if it fits the :func:`memory_budget`,
    else a PrefilterError stating the estimate and the limit, raised before anything is
    allocated."""
    budget = memory_budget()
    if not nbytes <= budget:
        raise PrefilterError(
            f"{what}: needs about {format_bytes(nbytes)}, more than the memory budget of "
            f"{format_bytes(budget)} (set {MEMORY_BUDGET_ENV} to change it)")
    return int(nbytes)


def broadcast_batch(**shapes) -> tuple:
    """The common batch shape of named arguments' batch ``shapes``, or a PrefilterError naming
    them (instead of NumPy's anonymous broadcasting ValueError)."""
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        desc = ", ".join(f"{k} {tuple(v)}" for k, v in shapes.items())
        raise PrefilterError(f"{', '.join(shapes)}: batch shapes do not broadcast ({desc})") \
            from None


def as_unit_interval(x, name: str) -> np.ndarray:
    """Finite numbers in ``[0, 1]`` (reflectances, probabilities)."""
    a = as_float_array(x, name)
    if np.any((a < 0.0) | (a > 1.0)):
        raise PrefilterError(f"{name}: expected numbers in [0, 1], got {_describe(a)}")
    return a
