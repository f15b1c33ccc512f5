"""Input validation helpers used at public API boundaries.

Each helper returns a clean float64 array or raises :class:`~prefilter.errors.PrefilterError` whose
message says which parameter was wrong, what it was and what was expected.
"""

from __future__ import annotations

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
    """A NumPy Generator; an int seeds a fresh one, ``None`` is rejected (determinism)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    raise PrefilterError(
        f"{name}: expected a numpy.random.Generator or an integer seed, got {type(rng).__name__}"
    )


def as_positive_int(n, name: str, *, lo: int = 1) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or int(n) < lo:
        raise PrefilterError(f"{name}: expected an integer >= {lo}, got {n!r}")
    return int(n)


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
