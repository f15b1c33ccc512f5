"""Schlick's Fresnel approximation (Schlick 1994, eq. 24): the one copy every method calls.

:func:`schlick_formula` is plain arithmetic, so the array API (:func:`schlick`) and the Numba
kernels (:data:`schlick_jit`, inlined) evaluate the same expression.
"""

from __future__ import annotations

import numpy as np

from prefilter.jit import njit_inline


def schlick_formula(f0, c):
    """``f0 + (1 - f0) (1 - c)^5`` for a cosine ``c`` already clamped to ``[0, 1]``."""
    return f0 + (1.0 - f0) * (1.0 - c) ** 5


#: :func:`schlick_formula` compiled for kernels (scalars; clamp the cosine first).
schlick_jit = njit_inline(schlick_formula)


def schlick(f0, cos_theta) -> np.ndarray:
    """Schlick Fresnel for reflectances ``f0`` and cosines ``cos_theta`` (broadcast together).

    For RGB reflectances ``f0 (..., 3)`` pass ``cos_theta[..., None]``. Cosines are clamped to
    ``[0, 1]`` (Schlick 1994, eq. 24).
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    return schlick_formula(np.asarray(f0, dtype=np.float64), c)
