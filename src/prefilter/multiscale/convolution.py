"""Overall roughness of a footprint: micro-scale GGX convolved with meso-scale normals.

Tao et al. 2021, eqs. 6-7. Both scales are isotropic LTCs ``diag(a, a, 1)``, i.e. GGX
distributions of normals weighted by projected area (:mod:`prefilter.multiscale.meso`). Their
spherical convolution (eq. 6) is the distribution of ``m = R_b m'`` with ``b ~ LTC(alpha_meso)``
and ``m' ~ LTC(alpha_micro)``, sampled here by Monte Carlo.

Fitting one isotropic LTC to the convolution (our choice, documented in ``docs/multiscale.md``):
maximum likelihood over the samples above the horizon, i.e. the ``alpha`` minimising the KL
divergence from the convolved lobe to the LTC family. Setting the derivative of the GGX/LTC
log-likelihood to zero gives ``mean(c a^2 / (s + c a^2)) = 1/2`` (``c = m_z^2``, ``s = 1 - c``),
monotone in ``a`` and solved by bisection.

Three ways to get ``alpha_total`` (``alpha_total(..., variant=...)``):

``"fit"`` (default)
    Our refit of the maximum-likelihood alphas on a 32 x 32 grid of ``(0, 1]^2``:
    ``alpha^2 = a_mi^2 + a_me^2 + a_mi a_me (c0 + c1 p + c2 p^2 + c3 q)`` with ``p = a_mi + a_me``,
    ``q = a_mi a_me`` (:data:`FIT_COEFFS`). The form is exact at ``a_me = 0`` (a flat footprint
    keeps the micro roughness) and symmetric, as the convolution of zonal lobes commutes.
``"paper"``
    Eq. 7, ``0.07 a_mi^2 + 0.94 a_mi + a_me - 0.83 a_mi a_me``.
``"mrl"``
    Matching the mean resultant length instead of the likelihood. It is exact in closed form:
    the mean resultant lengths of zonal lobes multiply under convolution
    (``E[m_z] = E[b_z] E[m'_z]``), so ``alpha = r^-1(r(a_mi) r(a_me))`` with ``r`` = eq. 4.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import (as_directions, as_float_array, as_positive_int, as_rng,
                                  check_scalar)
from prefilter.errors import PrefilterError
from prefilter.multiscale.meso import _alpha_from_r, _mrl
from prefilter.sphere.sampling import cosine_hemisphere, frame_from_normal, to_world

__all__ = [
    "FIT_COEFFS",
    "PAPER_EQ7",
    "alpha_total",
    "convolution_grid",
    "convolve_samples",
    "fit_alpha_ml",
    "fit_polynomial",
    "polynomial_paper_form",
    "sample_ltc_iso",
]

#: Tao et al. 2021, eq. 7: coefficients of (a_mi^2, a_mi, a_me, a_mi a_me).
PAPER_EQ7 = (0.07, 0.94, 1.0, -0.83)

#: Our fit (module docstring), produced by ``prefilter multiscale-fit`` (seed 0, 2^17 samples
#: per node, 32 x 32 grid uniform in sqrt(alpha) over [0.01, 1]): SSE 0.0102 on that grid
#: against 0.694 for eq. 7; see docs/multiscale.md.
FIT_COEFFS = (0.698232, 0.193748, -0.717994, 1.384903)

VARIANTS = ("fit", "paper", "mrl")


def _as_alpha(a, name: str) -> np.ndarray:
    a = as_float_array(a, name)
    if np.any((a < 0.0) | (a > 1.0)):
        raise PrefilterError(f"{name}: expected roughness in [0, 1], got range "
                             f"[{a.min():.4g}, {a.max():.4g}]")
    return a


def sample_ltc_iso(alpha, u) -> np.ndarray:
    """Directions ``(..., 3)`` from ``LTC(diag(alpha, alpha, 1))`` (= GGX normals weighted by
    ``m_z``) for uniforms ``u (..., 2)`` and ``alpha`` broadcasting against ``(...)``.

    Heitz et al. 2016, section 3: cosine sample, then ``M w / |M w|``.
    """
    c = cosine_hemisphere(u)
    a = as_float_array(alpha, "alpha")
    if np.any(a < 0.0):
        raise PrefilterError(f"alpha: expected roughness >= 0, got minimum {a.min():.4g}")
    a = a[..., None]
    w = np.concatenate([c[..., :2] * a, np.broadcast_to(c[..., 2:], np.broadcast_shapes(
        c[..., 2:].shape, a.shape))], axis=-1)
    # alpha = 0 with a cosine sample on the horizon gives w = 0: the lobe is the normal itself;
    # scaling by the largest component first keeps tiny alpha (1e-162) from underflowing |w|^2
    big = np.max(np.abs(w), axis=-1, keepdims=True)
    w = np.where(big > 0.0, w / np.where(big > 0.0, big, 1.0), np.array([0.0, 0.0, 1.0]))
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


def _meso_frames(alpha_meso, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    b = sample_ltc_iso(alpha_meso, u)
    t, bt = frame_from_normal(b)
    return t, bt, b


def _convolve(alpha_micro, frames, u) -> np.ndarray:
    return to_world(sample_ltc_iso(alpha_micro, u), *frames)


def convolve_samples(alpha_micro: float, alpha_meso: float, n: int, rng) -> np.ndarray:
    """``n`` samples ``(n, 3)`` of the spherical convolution of eq. 6 (Tao et al. 2021).

    ``m = R_b m'`` with ``b ~ LTC(alpha_meso)`` and ``m' ~ LTC(alpha_micro)``; ``R_b`` takes
    ``z`` to ``b`` (its azimuth is irrelevant since ``m'`` is isotropic). Some samples may fall
    below the horizon (``m_z < 0``). ``rng``: a Generator or an integer seed.
    """
    a_mi = check_scalar(alpha_micro, "alpha_micro", lo=0.0, hi=1.0)
    a_me = check_scalar(alpha_meso, "alpha_meso", lo=0.0, hi=1.0)
    n = as_positive_int(n, "n")
    u = as_rng(rng).random((n, 4))
    return _convolve(a_mi, _meso_frames(a_me, u[:, 0:2]), u[:, 2:4])


def fit_alpha_ml(m, *, iterations: int = 12) -> np.ndarray:
    """Maximum-likelihood isotropic LTC roughness of direction samples ``m (..., n, 3)``.

    Samples with ``m_z <= 0`` are ignored (the LTC family has no mass there). Returns ``(...)``:
    ``a = sqrt(x)`` with ``x`` the root in ``[0, 4]`` of ``h(x) = mean(c x / (s + c x)) - 1/2``
    (module docstring), by Newton's method safeguarded with bisection (``h`` is increasing).
    """
    m = as_directions(as_float_array(m, "m", ndim_min=2, last_dim=3), "m")
    iterations = as_positive_int(iterations, "iterations")
    up = m[..., 2] > 0.0
    if np.any(~up.any(-1)):
        # no data: the likelihood is flat and the root search would return its bracket end (2)
        raise PrefilterError("m: expected at least one direction above the horizon (m_z > 0) "
                             f"per batch entry, got none in {int((~up.any(-1)).sum())} of them")
    c = np.where(up, m[..., 2] ** 2, 0.0)
    s = 1.0 - c
    inv_count = 1.0 / np.maximum(up.sum(-1), 1)
    lo = np.zeros(m.shape[:-2])
    hi = np.full(m.shape[:-2], 4.0)
    # start: the mean-resultant-length match, close to the answer for small roughness
    x = _alpha_from_r(np.clip(np.where(up, m[..., 2], 0.0).sum(-1) * inv_count, 0.0, 1.0)) ** 2
    x = np.clip(x, 1e-8, 1.0)
    for _ in range(iterations):
        den = s + c * x[..., None]
        h = np.sum(c / den, -1) * x * inv_count - 0.5
        dh = np.sum(c * s / (den * den), -1) * inv_count
        lo = np.where(h < 0.0, x, lo)
        hi = np.where(h < 0.0, hi, x)
        step = x - h / np.maximum(dh, 1e-300)
        x = np.where((step > lo) & (step < hi), step, 0.5 * (lo + hi))
    return np.sqrt(x)


def convolution_grid(alpha_micro, alpha_meso, n: int = 1 << 16, seed=0) -> dict:
    """Monte Carlo convolution (eq. 6) and its fitted roughness on a grid.

    Common random numbers: every grid node uses the same ``n`` uniforms (from ``seed``), so the
    fitted surface is smooth in both arguments and the result is reproducible.

    Parameters
    ----------
    alpha_micro : array_like, shape (I,)
    alpha_meso : array_like, shape (J,)
    n : int
        Samples per node.

    Returns
    -------
    dict with ``alpha_micro (I,)``, ``alpha_meso (J,)``, ``alpha_ml (I, J)`` (maximum-likelihood
    fit), ``mrl (I, J)`` (Monte Carlo mean resultant length ``mean(m_z)``) and ``below (I, J)``
    (fraction of samples under the horizon).
    """
    ami = _as_alpha(alpha_micro, "alpha_micro").reshape(-1)
    ame = _as_alpha(alpha_meso, "alpha_meso").reshape(-1)
    n = as_positive_int(n, "n")
    u = as_rng(seed, "seed").random((n, 4))
    frames = _meso_frames(ame[:, None], u[:, 0:2])  # (J, n, 3) each, shared by all rows
    out = {k: np.zeros((len(ami), len(ame))) for k in ("alpha_ml", "mrl", "below")}
    for i, a in enumerate(ami):  # a loop over grid rows; samples are vectorised
        m = _convolve(a, frames, u[:, 2:4])
        out["alpha_ml"][i] = fit_alpha_ml(m)
        out["mrl"][i] = m[..., 2].mean(-1)
        out["below"][i] = (m[..., 2] <= 0.0).mean(-1)
    return {"alpha_micro": ami, "alpha_meso": ame, **out}


def eq7_paper_form(a, b, c0, c1, c2, c3):
    """Tao et al. 2021, eq. 7's form ``c0 a^2 + c1 a + c2 b + c3 a b`` (plain arithmetic: arrays,
    or scalars in the compiled shader, :mod:`prefilter.multiscale.kernels`)."""
    return c0 * a * a + c1 * a + c2 * b + c3 * a * b


def eq7_fit_form(a, b, c0, c1, c2, c3):
    """Our form of ``alpha_total`` (module docstring, ``"fit"``): ``sqrt(a^2 + b^2 + a b (c0 +
    c1 p + c2 p^2 + c3 q))``, ``p = a + b``, ``q = a b`` (plain arithmetic, as
    :func:`eq7_paper_form`)."""
    p = a + b
    q = a * b
    return np.sqrt(np.maximum(a * a + b * b + q * (c0 + p * (c1 + c2 * p) + c3 * q), 0.0))


def polynomial_paper_form(alpha_micro, alpha_meso, coeffs=PAPER_EQ7) -> np.ndarray:
    """Eq. 7's form ``c0 a_mi^2 + c1 a_mi + c2 a_me + c3 a_mi a_me`` (Tao et al. 2021)."""
    return eq7_paper_form(np.asarray(alpha_micro, float), np.asarray(alpha_meso, float), *coeffs)


def _ours(a, b, coeffs) -> np.ndarray:
    return eq7_fit_form(a, b, *coeffs)


def _design_ours(a, b) -> np.ndarray:
    p, q = a + b, a * b
    return np.stack([q, q * p, q * p * p, q * q], -1)


def fit_polynomial(grid: dict, form: str = "ours") -> dict:
    """Least-squares fit of ``alpha_total`` to a :func:`convolution_grid` result.

    ``form="paper"``: eq. 7's four monomials, linear least squares in ``alpha`` (as the paper).
    ``form="ours"``: the module docstring's form; linear least squares on ``alpha^2`` gives the
    start, then Gauss-Newton (scipy ``least_squares``) minimises the SSE in ``alpha``.

    Returns
    -------
    dict with ``coeffs`` (4,), ``sse`` (sum of squared errors in alpha over the grid), ``rmse``,
    ``max_abs`` and ``max_rel`` (relative to the fitted alphas).
    """
    if not isinstance(grid, dict) or any(k not in grid for k in ("alpha_micro", "alpha_meso",
                                                                 "alpha_ml")):
        raise PrefilterError("grid: expected the dict returned by convolution_grid (keys "
                             "alpha_micro, alpha_meso, alpha_ml)")
    ami = _as_alpha(grid["alpha_micro"], "grid['alpha_micro']").reshape(-1)
    ame = _as_alpha(grid["alpha_meso"], "grid['alpha_meso']").reshape(-1)
    y = as_float_array(grid["alpha_ml"], "grid['alpha_ml']")
    if y.shape != (ami.size, ame.size) or y.size < 4:
        raise PrefilterError(f"grid['alpha_ml']: expected shape ({ami.size}, {ame.size}) with at "
                             f"least 4 nodes (4 coefficients), got {y.shape}")
    A, B = np.meshgrid(ami, ame, indexing="ij")
    a, b, y = A.ravel(), B.ravel(), y.ravel()
    if form == "paper":
        X = np.stack([a * a, a, b, a * b], -1)
        coeffs = np.linalg.lstsq(X, y, rcond=None)[0]
        pred = X @ coeffs
    elif form == "ours":
        from scipy.optimize import least_squares

        X = _design_ours(a, b)
        start = np.linalg.lstsq(X, y * y - a * a - b * b, rcond=None)[0]
        res = least_squares(lambda c: _ours(a, b, c) - y, start, method="lm", xtol=1e-14,
                            ftol=1e-14)
        coeffs = res.x
        pred = _ours(a, b, coeffs)
    else:
        raise PrefilterError(f"form: expected 'ours' or 'paper', got {form!r}")
    return _errors(pred, y, coeffs)


def _errors(pred, y, coeffs) -> dict:
    e = pred - y
    return {"coeffs": np.asarray(coeffs, float), "sse": float(np.sum(e * e)),
            "rmse": float(np.sqrt(np.mean(e * e))), "max_abs": float(np.max(np.abs(e))),
            "max_rel": float(np.max(np.abs(e) / np.maximum(y, 1e-12)))}


def grid_errors(grid: dict, variant: str) -> dict:
    """Errors of ``alpha_total(..., variant)`` against a grid's maximum-likelihood alphas."""
    A, B = np.meshgrid(grid["alpha_micro"], grid["alpha_meso"], indexing="ij")
    pred = _alpha_total(A, B, variant, clamp=False)
    coeffs = {"fit": FIT_COEFFS, "paper": PAPER_EQ7}.get(variant, ())
    return _errors(pred.ravel(), grid["alpha_ml"].ravel(), coeffs)


def _alpha_total(a, b, variant: str, *, clamp: bool = True) -> np.ndarray:
    if variant == "fit":
        out = _ours(a, b, FIT_COEFFS)
    elif variant == "paper":
        out = polynomial_paper_form(a, b, PAPER_EQ7)
    elif variant == "mrl":
        out = _alpha_from_r(_mrl(a) * _mrl(b))
    else:
        raise PrefilterError(f"variant: expected one of {', '.join(VARIANTS)}, got {variant!r}")
    return np.clip(out, 0.0, 1.0) if clamp else out


def alpha_total(alpha_micro, alpha_meso, variant: str = "fit") -> np.ndarray:
    """Roughness of the isotropic LTC fitted to micro- convolved with meso-scale normals.

    Tao et al. 2021, eq. 7 (``variant="paper"``), our refit (``"fit"``, default) or mean
    resultant length matching (``"mrl"``); see the module docstring.

    Parameters
    ----------
    alpha_micro, alpha_meso : array_like, broadcasting shapes (...)
        Roughness of each scale, in ``[0, 1]``.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``alpha_total`` clamped to ``[0, 1]`` (the LTC table's range).
    """
    a = _as_alpha(alpha_micro, "alpha_micro")
    b = _as_alpha(alpha_meso, "alpha_meso")
    return _alpha_total(a, b, variant)
