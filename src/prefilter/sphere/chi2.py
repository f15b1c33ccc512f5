"""Chi-square goodness-of-fit test for samplers on the sphere (after Mitsuba's ``chi2.py``).

The sphere is cut into bins of equal solid angle inside a cap (``axis``, ``theta_max``) plus one
bin for everything outside; the histogram of the samples is compared with the density integrated
over each bin by Gauss-Legendre quadrature. Bins expecting fewer than ``min_expected`` samples are
pooled. A cap around the lobe keeps the test sharp for narrow lobes (alpha = 0.02), where bins over
the whole sphere would put every sample in one bin and the test could not fail.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import stats

from prefilter._validate import as_directions, as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.sphere.sampling import frame_from_normal, to_local, to_world


def _as_samples(samples) -> np.ndarray:
    s = as_float_array(samples, "samples", ndim_min=2, last_dim=3)
    if s.ndim != 2 or s.shape[0] == 0:
        raise PrefilterError(f"samples: expected shape (n, 3) with n >= 1, got {s.shape}")
    return as_directions(s, "samples")


def _as_axis(axis) -> np.ndarray:
    a = as_float_array(axis, "axis", ndim_min=1, last_dim=3)
    norm = np.linalg.norm(a)
    if a.shape != (3,) or not norm > 0.0:
        raise PrefilterError(f"axis: expected a non-zero vector of shape (3,), got {a.tolist()}")
    return a / norm


@dataclass(frozen=True)
class Chi2Result:
    """Outcome of :func:`chi2_sphere`."""

    p_value: float
    statistic: float
    dof: int
    n_samples: int
    mass_in_cap: float
    message: str = ""

    def passed(self, significance: float = 0.01) -> bool:
        return self.p_value > significance


def lobe_cap(samples, quantile: float = 0.995) -> tuple[np.ndarray, float]:
    """Axis (normalised mean direction) and angle containing ``quantile`` of ``samples (n, 3)``.

    Use pilot samples (a different seed from the tested ones) so the bins do not depend on them.
    """
    s = _as_samples(samples)
    q = float(as_float_array(quantile, "quantile"))
    if not 0.0 < q <= 1.0:
        raise PrefilterError(f"quantile: expected a number in (0, 1], got {quantile!r}")
    axis = s.mean(axis=0)
    norm = np.linalg.norm(axis)
    axis = np.array([0.0, 0.0, 1.0]) if norm < 1e-6 else axis / norm
    ang = np.arccos(np.clip(s @ axis, -1.0, 1.0))
    theta_max = float(min(np.pi, np.quantile(ang, q) * 1.05 + 1e-6))
    return axis, theta_max


def chi2_sphere(
    samples,
    pdf: Callable[[np.ndarray], np.ndarray],
    *,
    axis=(0.0, 0.0, 1.0),
    theta_max: float = np.pi,
    res: tuple[int, int] = (16, 32),
    quad: int = 6,
    min_expected: float = 5.0,
    max_refine: int = 8,
    refine_tol: float = 0.05,
    max_in_empty: int = 10,
    max_cells: int = 16384,
) -> Chi2Result:
    """Chi-square test of ``samples (n, 3)`` against the solid-angle density ``pdf(w (..., 3))``.

    Bins: ``res[0]`` rings of equal solid angle in ``cos`` of the angle to ``axis`` within
    ``theta_max``, times ``res[1]`` azimuthal sectors, plus the outside of the cap. Each bin's
    mass uses ``quad x quad`` Gauss-Legendre nodes, split adaptively (up to ``max_refine`` times)
    until a split changes it by less than ``refine_tol`` standard deviations of its count
    (at most ``max_cells`` new cells per level, the worst first).
    More than ``max_in_empty`` samples in bins of zero density fail the test outright.
    """
    samples = _as_samples(samples)
    n = samples.shape[0]
    axis = _as_axis(axis)
    if not callable(pdf):
        raise PrefilterError(f"pdf: expected a callable density, got {type(pdf).__name__}")
    theta_max = float(as_float_array(theta_max, "theta_max"))
    if not 0.0 < theta_max <= np.pi:
        raise PrefilterError(f"theta_max: expected an angle in (0, pi], got {theta_max!r}")
    if not (isinstance(res, (tuple, list)) and len(res) == 2):
        raise PrefilterError(f"res: expected (n_theta, n_phi), got {res!r}")
    n_th, n_ph = (as_positive_int(r, "res") for r in res)
    quad = as_positive_int(quad, "quad")
    t, b = frame_from_normal(axis)
    cmin = np.cos(theta_max)

    # Histogram in the cap frame.
    loc = to_local(samples, t, b, axis)
    cz = np.clip(loc[:, 2], -1.0, 1.0)
    ph = np.mod(np.arctan2(loc[:, 1], loc[:, 0]), 2 * np.pi)
    inside = cz >= cmin
    i = np.clip(((1.0 - cz[inside]) / (1.0 - cmin) * n_th).astype(int), 0, n_th - 1)
    j = np.clip((ph[inside] / (2 * np.pi) * n_ph).astype(int), 0, n_ph - 1)
    observed = np.zeros(n_th * n_ph + 1)
    np.add.at(observed, i * n_ph + j, 1.0)
    observed[-1] = n - inside.sum()

    # Expected counts: Gauss-Legendre over (cos, phi) in each bin; d(omega) = d(cos) d(phi).
    # Bins where a 2 x 2 split changes the mass by more than a small fraction of the count's
    # standard deviation are split again (pdfs of BRDF lobes jump at the horizon).
    x, wq = np.polynomial.legendre.leggauss(quad)
    dc = (1.0 - cmin) / n_th
    dp = 2 * np.pi / n_ph
    ii, jj = np.meshgrid(np.arange(n_th), np.arange(n_ph), indexing="ij")
    c0 = (1.0 - dc * (ii + 1)).ravel()
    p0 = (dp * jj).ravel()
    cells = (np.arange(n_th * n_ph), c0, c0 + dc, p0, p0 + dp)

    def cell_mass(c_a, c_b, p_a, p_b):
        cq = c_a[:, None] + (c_b - c_a)[:, None] * (x[None, :] + 1) / 2
        pq = p_a[:, None] + (p_b - p_a)[:, None] * (x[None, :] + 1) / 2
        C, P = cq[:, :, None], pq[:, None, :]
        sn = np.sqrt(np.maximum(0.0, 1.0 - C * C))
        local = np.stack(np.broadcast_arrays(sn * np.cos(P), sn * np.sin(P), C), axis=-1)
        dens = np.asarray(pdf(to_world(local, t, b, axis)), dtype=np.float64)
        if not np.all(np.isfinite(dens) & (dens >= 0.0)):
            # a NaN density would turn the statistic into NaN, a silent failure
            bad = dens[~(np.isfinite(dens) & (dens >= 0.0))]
            raise PrefilterError(f"pdf: expected finite densities >= 0, got {bad[:4]}")
        w2 = wq[:, None] * wq[None, :] / 4
        return np.sum(dens * w2, axis=(-2, -1)) * (c_b - c_a) * (p_b - p_a)

    mass = np.zeros(n_th * n_ph)
    coarse = cell_mass(*cells[1:])
    # Force-refining bins that hold samples but (apparently) no mass finds slivers of mass cut
    # off by a jump; not worth it when so many samples sit there that the sampler is wrong.
    force = observed[:-1][(coarse * n < 1e-3)].sum() <= 100 * max_in_empty
    for level in range(max_refine + 1):
        idx, ca, cb, pa, pb = cells
        cm, pm = (ca + cb) / 2, (pa + pb) / 2
        kids = (
            np.concatenate([idx] * 4),
            np.concatenate([ca, ca, cm, cm]),
            np.concatenate([cm, cm, cb, cb]),
            np.concatenate([pa, pm, pa, pm]),
            np.concatenate([pm, pb, pm, pb]),
        )
        kid_mass = cell_mass(*kids[1:])
        fine = kid_mass.reshape(4, -1).sum(axis=0)
        tol = refine_tol * np.sqrt(np.maximum(np.abs(fine), 1e-12) / max(n, 1))
        # Samples in a bin whose quadrature saw no mass: a thin sliver may have been missed.
        missed = force & (observed[idx] > 0) & (fine * n < 1e-3)
        err = np.abs(fine - coarse)
        ok = (err <= tol) & ~missed
        if level == max_refine:
            ok[:] = True
        elif (~ok).sum() > max_cells // 4:
            # Bound memory and time: split only the cells with the largest excess error.
            excess = np.where(ok, -np.inf, np.where(missed, np.inf, err / tol))
            keep = np.argsort(excess)[: excess.size - max_cells // 4]
            ok[keep] = True
        np.add.at(mass, idx[ok], fine[ok])
        if np.all(ok):
            break
        sel = np.tile(~ok, 4)
        cells = tuple(k[sel] for k in kids)
        coarse = kid_mass[sel]
    mass_cap = float(mass.sum())
    expected = np.concatenate([mass, [max(0.0, 1.0 - mass_cap)]]) * n

    # Samples where the density integrates to nothing fail outright; a handful are pooled with
    # the low-count bins instead (a quadrature can miss a sliver of a bin cut by a jump).
    empty = expected < 1e-9 * n
    if observed[empty].sum() > max_in_empty:
        return Chi2Result(0.0, np.inf, 0, n, mass_cap, "samples fell in bins of zero density")
    obs, exp = observed, expected

    low = exp < min_expected
    if np.any(low):
        pooled_o, pooled_e = obs[low].sum(), exp[low].sum()
        obs, exp = obs[~low], exp[~low]
        if pooled_e >= min_expected or exp.size == 0:
            obs, exp = np.append(obs, pooled_o), np.append(exp, pooled_e)
        else:
            k = int(np.argmin(exp))
            obs[k] += pooled_o
            exp[k] += pooled_e
    dof = exp.size - 1
    if dof < 1:
        return Chi2Result(1.0, 0.0, 0, n, mass_cap, "a single bin: the test cannot discriminate")
    stat = float(np.sum((obs - exp) ** 2 / exp))
    p = float(stats.chi2.sf(stat, dof))
    return Chi2Result(p, stat, dof, n, mass_cap)
