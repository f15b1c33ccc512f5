"""Fitting the isotropic GGX LTC table (Heitz, Dupuy, Hill, Neubelt 2016, section 4).

For one view angle ``theta`` and roughness ``alpha`` the normalised cosine-weighted lobe
``p(wi) = GGX.eval(wo, wi) / n`` (``n`` = albedo) is approximated by an LTC ``q = LTC(M).eval``.
The view lies in the xz plane, ``wo = (sin theta, 0, cos theta)``, so the lobe is symmetric about
that plane and ``M = [[a, 0, b], [0, c, 0], [d, 0, e]]`` (4 degrees of freedom up to scale)::

    M = [X Y Z] @ [[m11, 0, m13], [0, m22, 0], [0, 0, 1]],  Z = (sin beta, 0, cos beta)

fitted as ``(log m11, log m22, m13 / m11, beta)``. The paper's reference code pins ``Z`` to the
lobe's average direction (3 numbers); freeing ``beta`` halves the L1 distance at grazing views
(docs/ltc.md). The objective is ``integral |p - q|^k`` (``k = FitSettings.power``) estimated on two
FIXED stratified sample sets (cosine samples mapped by ``M``, and visible-normal reflections of the
GGX lobe) combined with the balance heuristic, so it is a deterministic function of the
parameters; Nelder-Mead minimises it, warm-started from the neighbouring (larger) roughness along
each view angle (cold start at alpha = 1 around the lobe's average direction).

:func:`refine_entry` is a second fitting stage that was tried and not adopted (docs/ltc.md,
"Probe-light refit"): Nelder-Mead on the log-ratio of the LTC's integrals over fixed probe
quads to their Monte Carlo references. It lowers the mean quad-light error and raises the median.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from prefilter.distributed import Engine
from prefilter.fileio import Checkpoints, bake_lock, save_npz_atomic, user_data_dir
from prefilter.validation import as_positive_int, as_roughness
from prefilter.errors import PrefilterError
from prefilter.microfacet import GGX, reflect
from prefilter.sphere.sampling import cosine_hemisphere

#: Version of the table layout written by :func:`bake_table` (checked by ``GGXTable.load``).
TABLE_VERSION = 1


#: Fitting objectives of the bake (``FitSettings.objective``).
OBJECTIVES = ("density", "quads")


@dataclass(frozen=True)
class QuadFitSettings:
    """The ``quads`` objective of the bake (:func:`quad_refit_row`).

    Per entry, the mean over ``probes`` fixed quad lights of ``|n E_k(M) / r_k - 1|^power``
    (the acceptance test's relative error), with ``r_k`` Monte Carlo references; probes whose
    reference is below ``threshold`` are left out, as the acceptance test leaves them out. The
    probes are drawn from the acceptance distribution (``validate.random_quads``, 20 %
    straddling the horizon) with ``seed`` (never 0, the acceptance seed), the same quads for every
    entry, plus ``probes_lobe`` quads centred on directions drawn from the entry's own lobe.
    """

    probes: int = 128
    probes_lobe: int = 0
    seed: int = 1
    lobe_samples: int = 2048
    light_samples: int = 256
    threshold: float = 1e-3
    #: 0.5 lowers both the median and the 90th percentile; 1 (the mean relative error) trades
    #: the median for the tail (docs/ltc.md).
    power: float = 0.5
    iterations: int = 40

    def probe_settings(self) -> ProbeSettings:
        return ProbeSettings(probes_random=self.probes, probes_lobe=self.probes_lobe,
                             seed=self.seed, lobe_samples=self.lobe_samples,
                             light_samples=self.light_samples)


@dataclass(frozen=True)
class FitSettings:
    """Everything that determines the baked bytes (stored in the table as JSON)."""

    res_theta: int = 64
    res_alpha: int = 64
    alpha_min: float = 0.01
    #: Last row's view angle (degrees); views beyond it are clamped to it at lookup.
    theta_max_deg: float = 88.0
    #: Stratified samples per axis of each fixed sample set (LTC and GGX): n_fit^2 each.
    n_fit: int = 32
    #: Gauss-Legendre nodes per axis for the magnitude, Fresnel and average-direction quadrature.
    quad_nodes: int = 96
    #: Exponent k of the fitting distance integral |p - q|^k (3 in the paper's reference code;
    #: smaller k weighs the lobe's tails, larger k the lobe's body, where highlights are: the
    #: shipped table uses 1, the best trade-off measured in docs/ltc.md).
    power: float = 1.0
    seed: int = 0
    #: ``"density"``: the fit above only; ``"quads"``: then refit every row on quad-light
    #: integrals (:func:`quad_refit_row` with ``quad``), the acceptance test's error measure.
    objective: str = "density"
    quad: QuadFitSettings | None = None

    def __post_init__(self):
        # checked here, before any work: a bad value would only show in the finished table
        as_positive_int(self.res_theta, "res_theta", lo=2)
        as_positive_int(self.res_alpha, "res_alpha", lo=2)
        as_positive_int(self.n_fit, "n_fit", lo=2)
        as_positive_int(self.quad_nodes, "quad_nodes", lo=2)
        as_positive_int(self.seed, "seed", lo=0)
        _in_range(self.alpha_min, "alpha_min", 1e-4, 1.0, hi_open=True)
        _in_range(self.theta_max_deg, "theta_max_deg", 0.0, 90.0, lo_open=True, hi_open=True)
        _in_range(self.power, "power", 0.1, 4.0)
        if self.objective not in OBJECTIVES:
            raise PrefilterError(f"objective: expected one of {OBJECTIVES}, got "
                                 f"{self.objective!r}")
        if self.objective == "quads" and self.quad is None:
            object.__setattr__(self, "quad", QuadFitSettings())

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Table axes ``t = sqrt(1 - cos theta)`` (T,) and ``r = sqrt(alpha)`` (R,)."""
        t_max = np.sqrt(1.0 - np.cos(np.radians(self.theta_max_deg)))
        axis_t = np.linspace(0.0, t_max, self.res_theta)
        axis_r = np.linspace(np.sqrt(self.alpha_min), 1.0, self.res_alpha)
        return axis_t, axis_r


def _in_range(x, name: str, lo: float, hi: float, *, lo_open: bool = False,
              hi_open: bool = False) -> float:
    """``x`` as a finite float in ``[lo, hi]`` (open ends as flagged), else a PrefilterError."""
    ok = isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)
    v = float(x) if ok else float("nan")
    above = lo < v if lo_open else lo <= v
    below = v < hi if hi_open else v <= hi
    if not (np.isfinite(v) and above and below):
        span = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise PrefilterError(f"{name}: expected a finite number in {span}, got {x!r}")
    return v


def view_from_t(t) -> np.ndarray:
    """View ``(..., 3)`` in the xz plane for table coordinate ``t = sqrt(1 - cos theta)``."""
    cos_t = 1.0 - np.asarray(t, dtype=np.float64) ** 2
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    return np.stack([sin_t, np.zeros_like(cos_t), cos_t], axis=-1)


def lobe_moments(wo, alpha, nodes: int = 96) -> dict[str, np.ndarray]:
    """Magnitude, Fresnel scalar and average direction of the isotropic GGX lobe.

    Heitz et al. 2016, section 4 (``equations.md`` 2): ``n = integral f cos dwi`` (albedo, F = 1),
    ``f5 = integral f cos (1 - wi.h)^5 dwi`` and the mean direction of ``f cos``. Deterministic
    Gauss-Legendre quadrature in the unit square of visible-normal sampling, where the integrand
    is ``G2 / G1`` times ``(1 - wo.m)^5`` or ``wi`` (``wi.h = wo.m`` for a reflection).

    Parameters
    ----------
    wo : (..., 3) views above the surface.
    alpha : (...) roughness.

    Returns
    -------
    dict with ``magnitude`` (...), ``fresnel`` (...), ``direction`` (..., 3) (unit).
    """
    wo = np.asarray(wo, dtype=np.float64)
    alpha = np.asarray(alpha, dtype=np.float64)
    x, w = np.polynomial.legendre.leggauss(nodes)
    x = (x + 1.0) / 2.0
    u = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    wgt = (w[:, None] * w[None, :]).reshape(-1) / 4.0
    model = GGX(alpha[..., None])
    wo_b = wo[..., None, :]
    m = model.sample_vndf(wo_b, u)
    wi = reflect(wo_b, m)
    lam_o = model.smith_lambda(wo_b)
    lam_i = model.smith_lambda(wi)
    ratio = np.where(wi[..., 2] > 0.0, (1.0 + lam_o) / (1.0 + lam_o + lam_i), 0.0) * wgt
    n = ratio.sum(-1)
    f5 = np.sum(ratio * (1.0 - np.clip(np.sum(wo_b * m, -1), 0.0, 1.0)) ** 5, -1)
    d = np.sum(ratio[..., None] * wi, -2)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return {"magnitude": n, "fresnel": f5, "direction": d}


def ltc_from_params(params) -> np.ndarray:
    """``M (3, 3)`` from ``(log m11, log m22, m13 / m11, beta)``.

    ``M = [X Y Z] @ [[m11, 0, m13], [0, m22, 0], [0, 0, 1]]`` with ``Z = (sin beta, 0, cos beta)``,
    ``X = (cos beta, 0, -sin beta)``, ``Y = (0, 1, 0)``: the general xz-symmetric LTC
    ``[[a, 0, b], [0, c, 0], [d, 0, e]]`` up to scale (4 degrees of freedom).
    """
    m11 = np.exp(params[0])
    m22 = np.exp(params[1])
    m13 = params[2] * m11
    zx, zz = np.sin(params[3]), np.cos(params[3])
    # columns X = (zz, 0, -zx), Y = (0, 1, 0), Z = (zx, 0, zz)
    return np.array(
        [
            [zz * m11, 0.0, zz * m13 + zx],
            [0.0, m22, 0.0],
            [-zx * m11, 0.0, -zx * m13 + zz],
        ]
    )


def normalize_ltc(M) -> np.ndarray:
    """``M`` divided by the length of its third column (the stored normalisation)."""
    M = np.asarray(M, dtype=np.float64)
    return M / np.linalg.norm(M[..., :, 2], axis=-1)[..., None, None]


def fixed_samples(n_fit: int, seed: int) -> np.ndarray:
    """Jittered stratified uniforms ``(n_fit^2, 2)``, fixed for the whole bake by ``seed``."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(n_fit), np.arange(n_fit), indexing="ij"), -1).reshape(-1, 2)
    return np.clip((g + rng.random(g.shape)) / n_fit, 1e-9, 1 - 1e-9)


def _lobe_and_pdf(wo, wi, alpha, lam_o):
    """Isotropic GGX ``eval(wo, wi)`` (cosine-weighted, ``equations.md`` 1) and the density of
    visible-normal reflection, sharing ``D(h)``: ``pdf = G1(wo) D(h) / (4 wo_z)`` for wo.h > 0.

    A fused form of ``GGX.eval`` and ``GGX.pdf_reflect`` for the fitting loop (no validation).
    """
    h = wi + wo
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    a2 = alpha * alpha
    t = (h[:, 0] ** 2 + h[:, 1] ** 2) / a2 + h[:, 2] ** 2
    D = np.where(h[:, 2] > 0.0, 1.0 / (np.pi * a2 * t * t), 0.0)
    wz2 = np.maximum(wi[:, 2] ** 2, 1e-300)
    s2 = a2 * (wi[:, 0] ** 2 + wi[:, 1] ** 2) / wz2
    lam_i = s2 / (1.0 + np.sqrt(1.0 + s2)) / 2.0
    scale = D / (4.0 * wo[2])
    f = np.where(wi[:, 2] > 0.0, scale / (1.0 + lam_o + lam_i), 0.0)
    pdf = np.where(h @ wo > 0.0, scale / (1.0 + lam_o), 0.0)
    return f, pdf


class _Objective:
    """``integral |p - q|^k / integral p^k`` for one (view, roughness), on fixed samples."""

    def __init__(self, wo, alpha, magnitude, u, power=0.5):
        self.power = power
        self.wo = wo
        self.alpha = alpha
        model = GGX(alpha)
        self.lam_o = float(model.smith_lambda(wo))
        self.n = magnitude
        self.c = cosine_hemisphere(u)  # cosine samples, mapped by M at every evaluation
        self.count = len(u)
        self.wb = reflect(wo, model.sample_vndf(wo, u))
        f, self.pdf_b = _lobe_and_pdf(wo, self.wb, alpha, self.lam_o)
        self.p_b = f / magnitude
        self.pk = np.sum(self.p_b**power / np.maximum(self.pdf_b, 1e-300)) / self.count

    def __call__(self, params) -> float:
        M = ltc_from_params(params)
        try:
            M_inv = np.linalg.inv(M)
        except np.linalg.LinAlgError:
            return np.inf  # a scale under/overflowed: Nelder-Mead steps back
        det_inv = abs(np.linalg.det(M_inv))
        if not (np.isfinite(det_inv) and det_inv > 0.0):
            return np.inf
        wl = self.c @ M.T
        wl /= np.linalg.norm(wl, axis=-1, keepdims=True)
        w = np.concatenate([wl, self.wb])
        lw = w @ M_inv.T
        length = np.linalg.norm(lw, axis=-1)
        q = np.maximum(0.0, lw[:, 2] / length) / np.pi * det_inv / length**3
        f_l, pdf_l = _lobe_and_pdf(self.wo, wl, self.alpha, self.lam_o)
        p = np.concatenate([f_l / self.n, self.p_b])
        pdf_b = np.concatenate([pdf_l, self.pdf_b])
        # balance heuristic over both sample sets: sum f / (N pdf_ltc + N pdf_b)
        err = np.sum(np.abs(p - q) ** self.power / np.maximum(q + pdf_b, 1e-300)) / self.count
        return float(err / self.pk)


def fit_entry(theta, alpha, *, init=None, n_fit: int = 32, seed: int = 0, quad_nodes: int = 96,
              power: float = 0.5):
    """Fit the LTC of one table entry.

    Parameters
    ----------
    theta : view angle from the normal (radians, in [0, pi/2)).
    alpha : GGX roughness.
    init : optional starting parameters ``(log m11, log m22, m13 / m11, beta)`` (a neighbour's
        fit); default: a cosine scaled by ``alpha`` around the lobe's average direction.

    Returns
    -------
    dict with ``M`` (3, 3) normalised by its third column, ``params`` (4,), ``magnitude``,
    ``fresnel``, ``error`` (the relative ``L^power`` objective at the optimum).
    """
    theta = float(theta)
    if not 0.0 <= theta < np.pi / 2:
        raise PrefilterError(f"theta: expected an angle in [0, pi/2), got {theta}")
    alpha = float(as_roughness(alpha, "alpha"))
    wo = np.array([np.sin(theta), 0.0, np.cos(theta)])
    return _fit(wo, alpha, init, fixed_samples(n_fit, seed), quad_nodes, power)


#: Relative fit error above which a warm-started entry is refitted from a fresh start.
RESTART_ERROR = 0.3

_NM = {"xatol": 1e-5, "fatol": 1e-7, "maxiter": 4000}


def _fit(wo, alpha, init, u, quad_nodes, power=0.5):
    mom = lobe_moments(wo, alpha, quad_nodes)
    obj = _Objective(wo, alpha, float(mom["magnitude"]), u, power)
    isotropic = wo[0] < 1e-12  # normal view: rotationally symmetric lobe, M = diag(a, a, 1)
    if init is None:
        d = mom["direction"]
        x0 = np.array([np.log(alpha), np.log(alpha), 0.0, np.arctan2(d[0], d[2])])
    else:
        x0 = np.asarray(init, dtype=np.float64)
    if isotropic:
        res = minimize(lambda s: obj(np.array([s[0], s[0], 0.0, 0.0])), x0[:1],
                       method="Nelder-Mead",
                       options={"initial_simplex": [[x0[0]], [x0[0] + 0.1]], **_NM})
        params = np.array([res.x[0], res.x[0], 0.0, 0.0])
    else:
        simplex = x0 + np.vstack([np.zeros(4), np.diag([0.1, 0.1, 0.05, 0.05])])
        res = minimize(obj, x0, method="Nelder-Mead", options={"initial_simplex": simplex, **_NM})
        params = res.x
    return {
        "M": normalize_ltc(ltc_from_params(params)),
        "params": params,
        "magnitude": float(mom["magnitude"]),
        "fresnel": float(mom["fresnel"]),
        "error": float(res.fun),
    }


def fit_row(t: float, settings: FitSettings, row: int = 0) -> dict[str, np.ndarray]:
    """Fit every roughness of one view angle (table coordinate ``t``), from alpha = 1 down.

    With ``settings.objective == "quads"`` the density fits are then refitted on quad-light
    integrals (:func:`quad_refit_row`; ``row`` seeds its references) and ``error`` is that
    objective.

    Returns arrays ``M`` (R, 3, 3), ``magnitude`` (R,), ``fresnel`` (R,), ``error`` (R,), in the
    order of the roughness axis (ascending).
    """
    _, axis_r = settings.axes()
    wo = view_from_t(t)
    u = fixed_samples(settings.n_fit, settings.seed)
    R = len(axis_r)
    out = {"M": np.zeros((R, 3, 3)), "magnitude": np.zeros(R), "fresnel": np.zeros(R),
           "error": np.zeros(R)}
    params = np.zeros((R, 4))
    init = None
    for j in range(R - 1, -1, -1):
        alpha = float(axis_r[j] ** 2)
        fit = _fit(wo, alpha, init, u, settings.quad_nodes, settings.power)
        if init is not None and fit["error"] > RESTART_ERROR:
            # Marching down in roughness can lose a sharp lobe at grazing views (the simplex
            # collapses onto a wide LTC); a fresh start from the lobe's mean direction recovers it.
            fresh = _fit(wo, alpha, None, u, settings.quad_nodes, settings.power)
            if fresh["error"] < fit["error"]:
                fit = fresh
        params[j] = fit["params"]
        init = fit["params"].copy()
        # the next (smaller) roughness scales both axes by about alpha_next / alpha
        if j > 0:
            init[:2] += 2.0 * np.log(axis_r[j - 1] / axis_r[j])
        for k in ("M", "magnitude", "fresnel", "error"):
            out[k][j] = fit[k]
    if settings.objective == "quads":
        refit = quad_refit_row(wo, axis_r**2, params, settings.quad,
                               magnitude=out["magnitude"], seed=row)
        out["M"], out["error"] = refit["M"], refit["error"]
    return out


#: File name of the table, in the package data and in the user data folder.
TABLE_NAME = "ggx_iso.npz"


def shipped_table_path() -> Path:
    """The table shipped with the package (package data; never written by a bake)."""
    return Path(__file__).with_name("data") / TABLE_NAME


def user_table_path() -> Path:
    """Where ``prefilter bake ltc-iso`` writes without ``-o``:
    :func:`prefilter.fileio.user_data_dir` ``/ ggx_iso.npz``."""
    return user_data_dir() / TABLE_NAME


def default_table_path() -> Path:
    """The table ``GGXTable.load()`` reads: the user table when one was baked, else the
    shipped one."""
    user = user_table_path()
    return user if user.is_file() else shipped_table_path()


def bake_table(
    out: str | os.PathLike | None = None,
    settings: FitSettings | None = None,
    *,
    processes: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    on_row: Callable[[int], None] | None = None,
    wait: bool = False,
) -> Path:
    """Fit the whole table row by row (resumable) and write it atomically to ``out`` (default:
    :func:`user_table_path`, which ``GGXTable.load()`` then prefers to the shipped table).

    Each row (:func:`fit_row`, one view angle) is an independent task run by
    :class:`prefilter.distributed.Engine` on ``scheduler`` (``None``: ``$DASK_SCHEDULER_ADDRESS``
    or this process; ``"local"``; a cluster's address), or on a local cluster of ``processes``
    workers when ``processes > 1``. Each finished row is checkpointed in ``<out>.parts/``;
    rerunning with the same settings resumes from there and gives the same bytes as an
    uninterrupted bake, wherever the rows ran. The bake holds
    :func:`prefilter.fileio.bake_lock` on ``out``: while another bake of ``out`` runs it raises
    a PrefilterError naming that bake (``wait=True``: waits for it). ``on_row(i)`` is called
    after row ``i`` is saved (tests use it to interrupt a bake).
    """
    settings = settings or FitSettings()
    if not isinstance(settings, FitSettings):
        raise PrefilterError(f"settings: expected FitSettings, got {type(settings).__name__}")
    as_positive_int(processes, "processes")
    out = Path(out) if out is not None else user_table_path()
    with bake_lock(out, wait=wait):
        with Engine(scheduler, workers=processes if processes > 1 else None) as engine:
            return _bake_locked(out, settings, engine, progress, on_row)


def _bake_locked(out: Path, settings: FitSettings, engine: Engine, progress: bool,
                 on_row: Callable[[int], None] | None) -> Path:
    axis_t, axis_r = settings.axes()
    key = {"version": TABLE_VERSION, **asdict(settings)}
    ck = Checkpoints(out, key)
    engine.run(fit_row, [(float(t), settings, i) for i, t in enumerate(axis_t)], ck,
               progress=progress, desc="ltc-iso rows", on_done=on_row)
    rows = [ck.load(i) for i in range(len(axis_t))]
    save_npz_atomic(
        out,
        version=np.array(TABLE_VERSION, dtype=np.int64),
        axis_t=axis_t,
        axis_r=axis_r,
        M=np.stack([r["M"] for r in rows]),
        magnitude=np.stack([r["magnitude"] for r in rows]),
        fresnel=np.stack([r["fresnel"] for r in rows]),
        fit_error=np.stack([r["error"] for r in rows]),
        settings=np.array(json.dumps(key, sort_keys=True)),
    )
    ck.clear()
    return out


# --------------------------------------------------------------------------------------------
# Second stage: refit on the quad-light integrals the table is used for
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ProbeSettings:
    """The probe-light refit (:func:`refine_entry`): an experiment, not used by the bake.

    ``probes_random`` quads from the acceptance distribution and ``probes_lobe`` quads around the
    lobe, drawn with ``seed`` (never 0, the acceptance seed); their MIS references use
    ``lobe_samples`` shared lobe samples and ``light_samples`` area samples per probe; the
    objective is ``mean |log((n E + eps n) / (r + eps n))|^power``.
    """

    probes_random: int = 64
    probes_lobe: int = 32
    seed: int = 1
    lobe_samples: int = 2048
    light_samples: int = 256
    eps: float = 1e-3
    power: float = 1.0


def params_from_ltc(M) -> np.ndarray:
    """Inverse of :func:`ltc_from_params` up to scale: ``(log m11, log m22, m13 / m11, beta)``.

    ``M (3, 3)`` of the form ``[[a, 0, b], [0, c, 0], [d, 0, e]]`` with ``det > 0``: the first
    column is ``m11 X``, the second ``m22 Y``, the third ``m13 X + Z`` (times a common scale).
    """
    M = np.asarray(M, dtype=np.float64)
    X = M[:, 0] / np.linalg.norm(M[:, 0])
    beta = np.arctan2(-X[2], X[0])
    Z = np.array([np.sin(beta), 0.0, np.cos(beta)])
    s = float(M[:, 2] @ Z)
    m11 = np.linalg.norm(M[:, 0]) / s
    return np.array([np.log(m11), np.log(M[1, 1] / s), float(M[:, 2] @ X) / s / m11, beta])


def _quads_around(c, rng) -> np.ndarray:
    """Parallelograms ``(k, 4, 3)`` centred at distance 1 in unit directions ``c (k, 3)``, as
    ``validate.random_quads`` draws them (half-sizes in [0.05, 0.6], tilt <= 60 deg, CCW from 0).
    """
    k = len(c)
    a = np.where(np.abs(c[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = np.cross(c, a)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(c, t1)
    g = rng.uniform(0, 2 * np.pi, (k, 1))
    tilt = np.radians(60) * np.sqrt(rng.random((k, 1)))
    nq = np.cos(tilt) * -c + np.sin(tilt) * (np.cos(g) * t1 + np.sin(g) * t2)
    b = np.where(np.abs(nq[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(nq, b)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(nq, e1)
    h = rng.uniform(0.05, 0.6, (k, 2))
    ea, eb = e1 * h[:, :1], e2 * h[:, 1:]
    # e1 x e2 = nq points towards the origin: this order is counter-clockwise seen from it
    return np.stack([c - ea - eb, c + ea - eb, c + ea + eb, c - ea + eb], 1)


def probe_quads(wo, alpha, settings: ProbeSettings) -> np.ndarray:
    """The fixed probe lights ``(K, 4, 3)`` of one table entry (view ``wo`` in the xz plane).

    ``probes_random`` quads from the acceptance distribution (``validate.random_quads``, 20 %
    straddling the horizon) drawn with ``settings.seed`` (never the acceptance seed 0), the same for
    every entry, plus ``probes_lobe`` quads centred on directions drawn from the entry's own lobe
    (visible-normal reflections), so that the peak is probed at every roughness.
    """
    from prefilter.ltc.validate import random_quads

    if settings.seed == 0:
        raise PrefilterError("seed: expected a seed other than 0 (the acceptance seed)")
    rng = np.random.default_rng([settings.seed, 1])
    ns = int(round(0.2 * settings.probes_random))  # noqa: RUF046  (numpy ints too)
    quads = [random_quads(ns, rng, straddle=True),
             random_quads(settings.probes_random - ns, rng)]
    if settings.probes_lobe:
        u = rng.random((settings.probes_lobe, 2))
        c = reflect(wo, GGX(alpha).sample_vndf(wo, u))
        # keep the centres above the horizon (a grazing lobe's reflections can dip below it)
        c[:, 2] = np.maximum(c[:, 2], 0.02)
        c /= np.linalg.norm(c, axis=-1, keepdims=True)
        quads.append(_quads_around(c, rng))
    return np.concatenate(quads)


def probe_references(wo, alpha, quads, n_lobe: int, n_light: int, seed) -> np.ndarray:
    """MIS estimates ``(K,)`` of ``integral_P f cos dwi`` over parallelograms ``quads (K, 4, 3)``.

    As ``validate.reference_quad_integral`` (balance heuristic, Veach 1997 eq. 9.15, between
    visible-normal reflections and uniform area samples of the light) but vectorised over the
    probes: ``n_lobe`` lobe samples shared by all probes, ``n_light`` area samples per probe.
    """
    rng = np.random.default_rng(seed)
    model = GGX(alpha)
    lam_o = float(model.smith_lambda(wo))
    v0, v1, v3 = quads[:, 0], quads[:, 1], quads[:, 3]
    ea, eb = v1 - v0, v3 - v0
    nrm = np.cross(ea, eb)
    area = np.linalg.norm(nrm, axis=-1)
    nq = nrm / area[:, None]
    d = np.sum(nq * v0, -1)

    def pdf_light(w):  # w (N, 3) -> (K, N): r^2 / (A |cos|) where the ray hits the quad
        cos = nq @ w.T
        safe = np.where(np.abs(cos) > 1e-12, cos, 1.0)
        t = np.where(np.abs(cos) > 1e-12, d[:, None] / safe, -1.0)
        p = t[..., None] * w[None] - v0[:, None]
        # parallelogram coordinates of the hit point
        aa, ab, bb = (np.sum(ea * ea, -1)[:, None], np.sum(ea * eb, -1)[:, None],
                      np.sum(eb * eb, -1)[:, None])
        pa, pb = np.sum(p * ea[:, None], -1), np.sum(p * eb[:, None], -1)
        det = aa * bb - ab * ab
        s1, s2 = (bb * pa - ab * pb) / det, (aa * pb - ab * pa) / det
        hit = (t > 0) & (s1 >= 0) & (s1 <= 1) & (s2 >= 0) & (s2 <= 1)
        return np.where(hit, t * t / (area[:, None] * np.maximum(np.abs(cos), 1e-300)), 0.0)

    wb = reflect(wo, model.sample_vndf(wo, rng.random((n_lobe, 2))))
    f_b, pb_b = _lobe_and_pdf(wo, wb, alpha, lam_o)
    pl_b = pdf_light(wb)
    z_b = np.where(pl_b > 0, f_b / np.maximum(n_lobe * pb_b + n_light * pl_b, 1e-300), 0.0)
    u = rng.random((len(quads), n_light, 2))
    pts = v0[:, None] + u[..., :1] * ea[:, None] + u[..., 1:] * eb[:, None]
    r = np.linalg.norm(pts, axis=-1)
    wl = (pts / r[..., None]).reshape(-1, 3)
    f_l, pb_l = _lobe_and_pdf(wo, wl, alpha, lam_o)
    f_l, pb_l = f_l.reshape(r.shape), pb_l.reshape(r.shape)
    pl_l = r * r / (area[:, None] * np.maximum(np.abs(np.sum(pts / r[..., None] * nq[:, None],
                                                                  -1)), 1e-300))
    z_l = f_l / np.maximum(n_lobe * pb_l + n_light * pl_l, 1e-300)
    return z_b.sum(-1) + z_l.sum(-1)


class _ProbeObjective:
    """``mean_k |log((n E_k(M) + eps) / (r_k + eps))|`` over the probe lights of one entry."""

    def __init__(self, quads, references, magnitude, eps, power=1.0):
        from prefilter.sphere.polygon import clip_to_horizon

        self.clipped = clip_to_horizon(quads)
        self.n = magnitude
        self.eps = eps
        self.power = power
        self.log_ref = np.log(np.maximum(references, 0.0) + eps)

    def __call__(self, params) -> float:
        from prefilter.sphere.polygon import polygon_integral

        M = ltc_from_params(params)
        det = np.linalg.det(M)
        if not (np.isfinite(det) and abs(det) > 1e-200 and np.all(np.isfinite(M))):
            return np.inf
        E = polygon_integral(M, self.clipped)
        return float(np.mean(np.abs(np.log(self.n * E + self.eps) - self.log_ref) ** self.power))


def refine_entry(wo, alpha, M, magnitude, settings: ProbeSettings) -> dict:
    """Second fitting stage: Nelder-Mead on the probe-light objective from ``M`` (warm start).

    Returns dict with ``M`` (3, 3) normalised, ``error`` (probe objective at the optimum) and
    ``error_start`` (at ``M``).
    """
    wo = np.asarray(wo, dtype=np.float64)
    quads = probe_quads(wo, alpha, settings)
    ref = probe_references(wo, alpha, quads, settings.lobe_samples,
                           settings.light_samples, [settings.seed, 2])
    obj = _ProbeObjective(quads, ref, magnitude, settings.eps * magnitude,
                          settings.power)
    x0 = params_from_ltc(M)
    f0 = obj(x0)
    if wo[0] < 1e-12:  # normal view: keep M = diag(a, a, 1)
        res = minimize(lambda s: obj(np.array([s[0], s[0], 0.0, 0.0])), x0[:1],
                       method="Nelder-Mead",
                       options={"initial_simplex": [[x0[0]], [x0[0] + 0.05]], **_NM_PROBE})
        params = np.array([res.x[0], res.x[0], 0.0, 0.0])
    else:
        simplex = x0 + np.vstack([np.zeros(4), np.diag([0.05, 0.05, 0.03, 0.03])])
        res = minimize(obj, x0, method="Nelder-Mead",
                       options={"initial_simplex": simplex, **_NM_PROBE})
        params = res.x
    if not res.fun < f0:
        return {"M": normalize_ltc(M), "error": f0, "error_start": f0}
    return {"M": normalize_ltc(ltc_from_params(params)), "error": float(res.fun),
            "error_start": f0}


_NM_PROBE = {"xatol": 1e-4, "fatol": 1e-6, "maxiter": 800}


# --------------------------------------------------------------------------------------------
# Quad-light objective: a batched Levenberg-Marquardt refit of whole rows
# --------------------------------------------------------------------------------------------


def _row_objective(params, clipped, ref, keep, n, power):
    """Per-entry objective ``(B,)`` and residuals ``(B, K)`` for parameters ``(B, 4)``."""
    from prefilter.sphere.polygon import polygon_integral

    M = np.stack([ltc_from_params(p) for p in params])
    good = np.all(np.isfinite(M), axis=(1, 2))
    det = np.linalg.det(np.where(good[:, None, None], M, np.eye(3)))
    good &= np.abs(det) > 1e-12
    M[~good] = np.eye(3)
    E = polygon_integral(M[:, None], clipped)
    res = np.where(keep, n[:, None] * E / np.where(keep, ref, 1.0) - 1.0, 0.0)
    f = np.sum(np.abs(res) ** power * keep, -1) / np.maximum(keep.sum(-1), 1)
    return np.where(good, f, np.inf), res


def quad_refit_row(wo, alphas, params0, settings: QuadFitSettings, *, magnitude=None,
                   seed=0) -> dict[str, np.ndarray]:
    """Refit the LTCs of one view angle on quad-light integrals, all roughnesses at once.

    Minimises :class:`QuadFitSettings`' mean relative quad-light error per entry by
    Levenberg-Marquardt with iteratively reweighted least squares (``power < 2``: weights
    ``|r|^(power - 2)``, floored), forward-difference Jacobians, one batched
    ``polygon_integral`` call per evaluation. Each entry only accepts steps that lower its own
    objective, so the result is never worse than ``params0`` on the probes.

    Parameters
    ----------
    wo : (3,) view in the xz plane. alphas : (B,) roughness. params0 : (B, 4) start
        ``(log m11, log m22, m13 / m11, beta)`` (the density fit).
    magnitude : optional (B,) albedos (default: :func:`lobe_moments`).
    seed : seed of the probes' Monte Carlo references (with the entry index).

    Returns
    -------
    dict with ``params`` (B, 4), ``M`` (B, 3, 3) normalised, ``error`` (B,) and ``error_start``
    (B,) (the objective at ``params0``).
    """
    from prefilter.sphere.polygon import clip_to_horizon

    wo = np.asarray(wo, dtype=np.float64)
    alphas = np.atleast_1d(np.asarray(alphas, dtype=np.float64))
    B = len(alphas)
    ps = settings.probe_settings()
    if magnitude is None:
        magnitude = lobe_moments(wo, alphas)["magnitude"]
    n = np.asarray(magnitude, dtype=np.float64)
    quads = np.stack([probe_quads(wo, a, ps) for a in alphas])
    ref = np.stack([probe_references(wo, a, q, ps.lobe_samples, ps.light_samples,
                                     [settings.seed, 3, int(seed), j])
                    for j, (a, q) in enumerate(zip(alphas, quads))])
    clipped = clip_to_horizon(quads)
    keep = ref >= settings.threshold
    # the normal view keeps M = diag(a, a, 1): one free parameter, tied log-scales
    basis = np.eye(4) if wo[0] > 1e-12 else np.array([[1.0], [1.0], [0.0], [0.0]])
    d = basis.shape[1]
    y = np.asarray(params0, dtype=np.float64) @ np.linalg.pinv(basis).T
    p = settings.power

    def evaluate(yy):
        return _row_objective(yy @ basis.T, clipped, ref, keep, n, p)

    f, r = evaluate(y)
    f_start = f.copy()
    lam = np.full(B, 1e-2)
    h = 1e-5
    for _ in range(settings.iterations):
        J = np.empty(r.shape + (d,))
        for i in range(d):
            yi = y.copy()
            yi[:, i] += h
            J[..., i] = (evaluate(yi)[1] - r) / h
        # IRLS weights for |r|^p, floored so that exact probes do not dominate
        w = keep * np.maximum(np.abs(r), 1e-3) ** (p - 2.0)
        A = np.einsum("bk,bki,bkj->bij", w, J, J)
        g = np.einsum("bk,bki,bk->bi", w, J, r)
        diag = np.einsum("bii->bi", A)
        step = -np.linalg.solve(A + lam[:, None, None] * (np.eye(d) * diag[:, None, :] + 1e-9
                                                           * np.eye(d)), g[..., None])[..., 0]
        f_new, r_new = evaluate(y + step)
        better = f_new < f
        y = np.where(better[:, None], y + step, y)
        r = np.where(better[:, None], r_new, r)
        f = np.where(better, f_new, f)
        lam = np.where(better, lam / 3.0, lam * 4.0)
        if np.all(lam > 1e8):
            break
    params = y @ basis.T
    return {"params": params, "M": normalize_ltc(np.stack([ltc_from_params(q) for q in params])),
            "error": f, "error_start": f_start}
