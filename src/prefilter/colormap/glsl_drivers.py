"""GLSL of the colour-map drivers beyond the table lookup: procedural noise, heights and slopes.

The shader code lives in ``shaders/noise.glsl``, ``shaders/height.glsl`` and
``shaders/slope.glsl`` (Heitz et al. 2013, sections 4.2, 5.1 and 5.2), each the float32 twin of
the compiled kernel or array function it names; this module writes the constants they read
(per-level noise variances, the probit table of :mod:`prefilter.colormap.height`, the slope
covariance, the slope stack's layout and Gauss-Hermite taps) and the ``erfc`` they share, and
packs a :class:`~prefilter.colormap.slope.SlopeColormapTable` as the texture ``slope.glsl`` reads.
The snippets follow :func:`prefilter.colormap.glsl.glsl_snippet` (they call its
``colormapFiltered``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError

__all__ = ["SHADER_DIR", "driver_glsl", "height_glsl", "noise_glsl", "slope_glsl",
           "slope_texture"]

SHADER_DIR = Path(__file__).resolve().parent / "shaders"


def _float(v) -> str:
    s = f"{float(v):.9g}"
    return s if any(ch in s for ch in ".en") else s + ".0"  # GLSL ES: no int -> float


def _array(name: str, values) -> str:
    v = np.ravel(np.asarray(values, np.float64))
    return f"const float {name}[{v.size}] = float[{v.size}]({', '.join(map(_float, v))});\n"


def _erfcx() -> str:
    """``colormapErfcx(x) = exp(x^2) erfc(x)``, ``x >= 0`` (the Chebyshev fit of
    :data:`prefilter.leadr.glsl.ERFC_COEFFS`, fractional error < 1.2e-7) and the Mills ratio
    ``colormapMills(z) = phi(z) / Phi(z)``."""
    from prefilter.leadr.glsl import ERFC_COEFFS

    c = ERFC_COEFFS
    poly = f"{c[-1]:.9g}"
    for k in c[-2:0:-1]:
        poly = f"{k:.9g} + t * ({poly})"
    poly = f"{c[0]:.9g} + t * ({poly})"
    return ("// exp(x^2) erfc(x), x >= 0 (Numerical Recipes' Chebyshev fit)\n"
            "float colormapErfcx(float x) {\n"
            "    float t = 1.0 / (1.0 + 0.5 * x);\n"
            f"    return t * exp({poly});\n}}\n"
            "// the Mills ratio phi(z) / Phi(z), stable for z << 0\n"
            "float colormapMills(float z) {\n"
            "    if (z < 0.0) return 0.79788456 / colormapErfcx(-z * 0.70710678);\n"
            "    float e = exp(-0.5 * z * z);\n"
            "    return 0.39894228 * e / (1.0 - 0.5 * colormapErfcx(z * 0.70710678) * e);\n}\n")


def _code(name: str) -> str:
    return (SHADER_DIR / name).read_text()


def noise_glsl(noise_std=None) -> str:
    """``colormapNoiseSigma(areaLod)`` with the per-level variances of ``noise_std``
    (:class:`prefilter.colormap.texture.NoiseStd`; ``None``: a single level of variance 0)."""
    var = np.zeros(1) if noise_std is None else np.asarray(noise_std.variance, np.float64)
    return (f"const int CM_NOISE_LEVELS = {var.size};\n" + _array("CM_NOISE_VAR", var)
            + _code("noise.glsl"))


def height_glsl(slope_cov=None) -> str:
    """``colormapLambda``, ``colormapHeightFootprint`` and ``colormapHeightNaive`` for a height
    map of slope covariance ``slope_cov (2, 2)`` (``None``: the identity), with
    ``colormapErfcx``."""
    from prefilter.colormap.height import _PROBIT_T, _probit_table

    c = np.eye(2) if slope_cov is None else np.asarray(slope_cov, np.float64)
    if c.shape != (2, 2):
        raise PrefilterError(f"slope_cov: expected a 2x2 covariance, got shape {c.shape}")
    kappa, d = _probit_table()
    t = _PROBIT_T
    head = (f"const vec3 CM_SLOPE_COV = vec3({_float(c[0, 0])}, {_float(c[1, 1])}, "
            f"{_float(c[0, 1])});\n"
            f"const int CM_PROBIT_N = {t.size};\n"
            f"const float CM_PROBIT_T0 = {_float(t[0])}, CM_PROBIT_DT = "
            f"{_float(t[1] - t[0])}, CM_PROBIT_LMIN = {_float(np.exp(t[0]))};\n"
            + _array("CM_PROBIT_KAPPA", kappa) + _array("CM_PROBIT_D", d))
    return _erfcx() + head + _code("height.glsl")


def slope_glsl(table=None, n_taps: int = 7, *, erfcx: bool = True) -> str:
    """``colormapSlope(wo, mu, cov)``, ``colormapSlopeNaive(mu)`` and their helpers for the
    stack ``table`` (:class:`~prefilter.colormap.slope.SlopeColormapTable`; ``None``: a
    placeholder 2 x 2 x 2 stack), ``n_taps`` Gauss-Hermite taps as
    :meth:`~prefilter.colormap.slope.SlopeColormapTable.lookup`; ``erfcx``: include
    ``colormapErfcx`` (leave it out after :func:`height_glsl`)."""
    from prefilter.colormap.slope import N_TAPS_MAX

    if not 1 <= int(n_taps) <= N_TAPS_MAX:
        raise PrefilterError(f"n_taps: expected an integer in [1, {N_TAPS_MAX}], got {n_taps}")
    x, w = np.polynomial.hermite_e.hermegauss(int(n_taps))
    w = w / w.sum()
    n, nl, e, smax = (2, 2, 1.0, 1.0) if table is None else (
        table.n, table.stack.shape[0], table.extent, table.sigma_max)
    head = (f"const int CM_SLOPE_N = {n}, CM_SLOPE_LEVELS = {nl}, CM_SLOPE_TAPS = {x.size};\n"
            f"const float CM_SLOPE_EXTENT = {_float(e)}, CM_SLOPE_SIGMA_MAX = {_float(smax)};\n"
            + _array("CM_SLOPE_X", x) + _array("CM_SLOPE_W", w))
    return (_erfcx() if erfcx else "") + head + _code("slope.glsl")


def slope_texture(table=None) -> np.ndarray:
    """The stack of ``table`` as ``slope.glsl``'s ``uCmSlopeStack``: ``(levels n, n, 4)``
    float32, level ``k`` in rows ``k n .. k n + n - 1``, alpha 1 (``None``: zeros, 4 x 2)."""
    if table is None:
        return np.zeros((4, 2, 4), np.float32)
    s = np.asarray(table.stack, np.float64)
    if s.shape[-1] == 1:
        s = np.repeat(s, 3, -1)
    nl, n = s.shape[:2]
    out = np.ones((nl * n, n, 4), np.float32)
    out[..., :3] = s[..., :3].reshape(nl * n, n, 3)
    return out


def driver_glsl(driver=None, slope_table=None) -> str:
    """Every driver's snippet for a :class:`prefilter.colormap.driver.ColormapDriver`
    ``driver`` (its noise std and slope covariance; ``None`` or other drivers: placeholders), and
    the slope stack ``slope_table``: appended to :func:`prefilter.colormap.glsl.glsl_snippet`."""
    noise = getattr(driver, "noise_std", None)
    cov = getattr(driver, "slope_cov", None)
    return (noise_glsl(noise) + height_glsl(cov)
            + slope_glsl(slope_table, erfcx=False))
