"""Chi-square goodness-of-fit test for samplers on the sphere (after Mitsuba's ``chi2.py``).

The sphere is cut into bins of equal solid angle inside a cap (``axis``, ``theta_max``) plus one
bin for everything outside; the histogram of the samples is compared with the density integrated
over each bin by Gauss-Legendre quadrature. Bins expecting fewer than ``min_expected`` samples are
pooled. A cap around the lobe keeps the test sharp for narrow lobes (alpha = 0.02), where bins over
the whole sphere would put every sample in one bin and the test could not fail.

For very narrow, anisotropic or grazing lobes (alpha 0.001, views at 89 deg) no cap works: the
lobe covers a sliver of a few bins whose density quadrature cannot resolve it. :func:`chi2_warped`
bins instead in a warp of the sphere onto the unit square (as Mitsuba's domains do), and
:func:`slope_warp` is one under which microfacet lobes fill the square evenly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import stats

from prefilter.validation import as_directions, as_float_array, as_positive_int
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
    above=None,
) -> Chi2Result:
    """Chi-square test of ``samples (n, 3)`` against the solid-angle density ``pdf(w (..., 3))``.

    Bins: ``res[0]`` rings of equal solid angle in ``cos`` of the angle to ``axis`` within
    ``theta_max``, times ``res[1]`` azimuthal sectors, plus the outside of the cap. Each bin's
    mass uses ``quad x quad`` Gauss-Legendre nodes, split adaptively (up to ``max_refine`` times)
    until a split changes it by less than ``refine_tol`` standard deviations of its count
    (at most ``max_cells`` new cells per level, the worst first).
    More than ``max_in_empty`` samples in bins of zero density fail the test outright.
    ``above``: a direction ``v (3,)``; the bins then cover only the cap's part with ``w.v > 0``
    (each cell's quadrature spans exactly that arc) and the rest joins the outside bin, e.g.
    ``(0, 0, 1)`` for a lobe tested on the upper hemisphere only, whose draws below the
    horizon (weight 0, or failed draws) are counted but not binned.
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
    p1_range = None
    if above is not None:
        v = _as_axis(above)
        inside &= samples @ v > 0.0
        p1_range = _arc_above(v @ axis, v @ t, v @ b)
    i = np.clip(((1.0 - cz[inside]) / (1.0 - cmin) * n_th).astype(int), 0, n_th - 1)
    j = np.clip((ph[inside] / (2 * np.pi) * n_ph).astype(int), 0, n_ph - 1)
    observed = np.zeros(n_th * n_ph + 1)
    np.add.at(observed, i * n_ph + j, 1.0)
    observed[-1] = n - inside.sum()

    # Cells in (cos, phi), where d(omega) = d(cos) d(phi).
    dc = (1.0 - cmin) / n_th
    dp = 2 * np.pi / n_ph
    ii, jj = np.meshgrid(np.arange(n_th), np.arange(n_ph), indexing="ij")
    c0 = (1.0 - dc * (ii + 1)).ravel()
    p0 = (dp * jj).ravel()
    cells = (np.arange(n_th * n_ph), c0, c0 + dc, p0, p0 + dp)

    def density(C, P):
        sn = np.sqrt(np.maximum(0.0, 1.0 - C * C))
        local = np.stack(np.broadcast_arrays(sn * np.cos(P), sn * np.sin(P), C), axis=-1)
        return _eval_pdf(pdf, to_world(local, t, b, axis))

    return _binned_test(observed, cells, density, quad=quad, min_expected=min_expected,
                        max_refine=max_refine, refine_tol=refine_tol,
                        max_in_empty=max_in_empty, max_cells=max_cells, p1_range=p1_range)


def _arc_above(vz, vx, vy):
    """``p1_range`` of the directions ``(sin cos p, sin sin p, c)`` with ``w.v > 0`` at each
    ``c``, for ``v = (vx, vy, vz)`` in the cap frame: ``c vz + sin r cos(p - p0) > 0`` with
    ``r = |(vx, vy)|``, an arc of azimuths around ``p0``, as two intervals of ``[0, 2 pi)``."""
    r = float(np.hypot(vx, vy))
    p0 = float(np.arctan2(vy, vx))
    two_pi = 2.0 * np.pi

    def p1_range(c):
        sn = np.sqrt(np.maximum(0.0, 1.0 - c * c)) * r
        pos = sn > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(pos, -c * vz / np.where(pos, sn, 1.0), np.where(c * vz > 0.0, -2.0, 2.0))
        half = np.arccos(np.clip(k, -1.0, 1.0))
        full = k <= -1.0
        lo = np.mod(p0 - half, two_pi)
        hi = lo + 2.0 * half
        zero = np.zeros_like(lo)
        return [(np.where(full, 0.0, lo), np.where(full, two_pi, np.minimum(hi, two_pi))),
                (zero, np.where(full, 0.0, np.maximum(hi - two_pi, 0.0)))]

    return p1_range


def _eval_pdf(pdf, w: np.ndarray) -> np.ndarray:
    dens = np.asarray(pdf(w), dtype=np.float64)
    if not np.all(np.isfinite(dens) & (dens >= 0.0)):
        # a NaN density would turn the statistic into NaN, a silent failure
        bad = dens[~(np.isfinite(dens) & (dens >= 0.0))]
        raise PrefilterError(f"pdf: expected finite densities >= 0, got {bad[:4]}")
    return dens


def _cell_masses(a0, b0, a1, b1, density, quad, p1_range=None):
    """Integrals of ``density(p0, p1)`` over the rectangles ``[a0, b0] x [a1, b1]`` (arrays),
    ``quad x quad`` Gauss-Legendre nodes; the inner rule spans only the chords ``p1_range(p0)``
    of the domain (see :func:`_binned_test`)."""
    x, wq = np.polynomial.legendre.leggauss(quad)
    q0 = a0[:, None] + (b0 - a0)[:, None] * (x[None, :] + 1) / 2
    if p1_range is None:
        q1 = a1[:, None] + (b1 - a1)[:, None] * (x[None, :] + 1) / 2
        dens = density(q0[:, :, None], q1[:, None, :])
        w2 = wq[:, None] * wq[None, :] / 4
        return np.sum(dens * w2, axis=(-2, -1)) * (b0 - a0) * (b1 - a1)
    inner = 0.0
    for lo, hi in p1_range(q0):
        lo = np.maximum(a1[:, None], lo)
        width = np.maximum(np.minimum(b1[:, None], hi) - lo, 0.0)
        q1 = lo[..., None] + width[..., None] * (x + 1) / 2
        dens = density(np.broadcast_to(q0[:, :, None], q1.shape), q1)
        inner = inner + np.sum(dens * wq, axis=-1) * width / 2
    return np.sum(inner * wq, axis=-1) * (b0 - a0) / 2


def _binned_test(observed, cells, density, *, quad, min_expected, max_refine, refine_tol,
                 max_in_empty, max_cells, p1_range=None) -> Chi2Result:
    """Chi-square statistic of ``observed`` (one count per cell, then the rest of the domain).

    ``cells = (index, a0, b0, a1, b1)`` are rectangles in a 2D parametrisation and
    ``density(p0, p1)`` the density per unit parameter area. Each bin's mass uses ``quad x quad``
    Gauss-Legendre nodes, split 2 x 2 adaptively (see :func:`chi2_sphere`). ``p1_range(p0)``,
    if given, bounds the domain: a list of intervals ``(lo, hi)`` of ``p1`` at each ``p0``; the
    inner rule then spans only those chords of a cell, so a density that vanishes outside the
    domain has no jump or kink inside a quadrature cell.
    """
    n = int(observed.sum())
    n_bins = observed.size - 1

    def cell_mass(a0, b0, a1, b1):
        return _cell_masses(a0, b0, a1, b1, density, quad, p1_range)

    # Bins where a 2 x 2 split changes the mass by more than a small fraction of the count's
    # standard deviation are split again (pdfs of BRDF lobes jump at the horizon).
    mass = np.zeros(n_bins)
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


def _warped_density(pdf, warp):
    """``pdf(w(u)) jac(u)`` at points ``(U, V)`` of the square: the density per unit area."""

    def density(U, V):
        w, jac = warp.from_square(np.stack(np.broadcast_arrays(U, V), axis=-1))
        dens = _eval_pdf(pdf, w)
        return np.where(jac > 0.0, dens * np.where(jac > 0.0, jac, 0.0), 0.0)

    return density


def warp_integral(f: Callable[[np.ndarray], np.ndarray], warp: "Warp", *,
                  res: tuple[int, int] = (16, 16), quad: int = 8) -> float:
    """Integral of ``f(w (..., 3)) >= 0`` over the domain of ``warp`` (solid angle), by
    ``quad x quad`` Gauss-Legendre nodes in each of ``res`` cells of its square (the inner rule
    over ``warp.v_range`` only). For a lobe's pdf under a warp that spreads it over the square
    (e.g. :func:`slope_warp` of its half vectors) this converges where a quadrature in
    spherical coordinates cannot resolve a narrow grazing lobe."""
    if not isinstance(warp, Warp):
        raise PrefilterError(f"warp: expected a prefilter.sphere.Warp, got {type(warp).__name__}")
    n_u, n_v = (as_positive_int(r, "res") for r in res)
    ii, jj = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    u0, v0 = (ii / n_u).ravel(), (jj / n_v).ravel()
    masses = _cell_masses(u0, u0 + 1.0 / n_u, v0, v0 + 1.0 / n_v, _warped_density(f, warp),
                          as_positive_int(quad, "quad"), warp.v_range)
    return float(np.sum(masses))


@dataclass(frozen=True)
class Warp:
    """A bijection between (part of) the sphere and the unit square, for :func:`chi2_warped`.

    ``to_square(w (n, 3)) -> u (n, 2)``: NaN for directions outside the warped domain.
    ``from_square(u (..., 2)) -> (w (..., 3), jac (...))``: ``jac = d(omega) / du`` (solid angle
    per unit area of the square), 0 where ``u`` has no image (``w`` is then any unit vector).
    Points ``u = (u, v)``.
    """

    to_square: Callable[[np.ndarray], np.ndarray]
    from_square: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    #: Optional ``v_range(u (...)) -> [(lo, hi), ...]``: the domain is the union of
    #: ``lo(u) <= v <= hi(u)`` in the square, so the quadrature never straddles its edge.
    v_range: Callable[[np.ndarray], list[tuple[np.ndarray, np.ndarray]]] | None = None


def chi2_warped(
    samples,
    pdf: Callable[[np.ndarray], np.ndarray],
    warp: Warp,
    *,
    res: tuple[int, int] = (32, 32),
    quad: int = 6,
    min_expected: float = 5.0,
    max_refine: int = 8,
    refine_tol: float = 0.05,
    max_in_empty: int = 10,
    max_cells: int = 16384,
) -> Chi2Result:
    """Chi-square test of ``samples (n, 3)`` against ``pdf(w (..., 3))`` with bins in a warp.

    As :func:`chi2_sphere`, but the bins are a ``res[0] x res[1]`` grid of the unit square of
    ``warp`` (plus one bin for the directions outside its domain), and each bin's mass is the
    integral of ``pdf(w(u)) jac(u)`` over the cell. Mitsuba's ``chi2.py`` bins in a domain's own
    parametrisation the same way. A warp under which the lobe is spread over the square (e.g.
    :func:`slope_warp` for microfacet lobes) keeps the density smooth per bin and the bins
    evenly filled, where caps around a very narrow, grazing lobe are neither. ``mass_in_cap``
    of the result is the mass inside the warped domain.
    """
    samples = _as_samples(samples)
    n = samples.shape[0]
    if not callable(pdf):
        raise PrefilterError(f"pdf: expected a callable density, got {type(pdf).__name__}")
    if not isinstance(warp, Warp):
        raise PrefilterError(f"warp: expected a prefilter.sphere.Warp, got {type(warp).__name__}")
    if not (isinstance(res, (tuple, list)) and len(res) == 2):
        raise PrefilterError(f"res: expected (n_u, n_v), got {res!r}")
    n_u, n_v = (as_positive_int(r, "res") for r in res)
    quad = as_positive_int(quad, "quad")

    u = np.asarray(warp.to_square(samples), dtype=np.float64)
    inside = np.all(np.isfinite(u) & (u >= 0.0) & (u <= 1.0), axis=-1)
    i = np.clip((u[inside, 0] * n_u).astype(int), 0, n_u - 1)
    j = np.clip((u[inside, 1] * n_v).astype(int), 0, n_v - 1)
    observed = np.zeros(n_u * n_v + 1)
    np.add.at(observed, i * n_v + j, 1.0)
    observed[-1] = n - inside.sum()

    ii, jj = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    u0, v0 = (ii / n_u).ravel(), (jj / n_v).ravel()
    cells = (np.arange(n_u * n_v), u0, u0 + 1.0 / n_u, v0, v0 + 1.0 / n_v)

    density = _warped_density(pdf, warp)

    return _binned_test(observed, cells, density, quad=quad, min_expected=min_expected,
                        max_refine=max_refine, refine_tol=refine_tol,
                        max_in_empty=max_in_empty, max_cells=max_cells, p1_range=warp.v_range)


def slope_warp(mean_slope=(0.0, 0.0), scale=((1.0, 0.0), (0.0, 1.0)), *, wo=None,
               reflect: bool = False, above=None, spread: float = 1.0) -> Warp:
    """Warp of microfacet normals, visible normals or reflected directions through slope space.

    A normal ``m`` (``m_z > 0``) has slope ``s = -m_xy / m_z = mean_slope + scale z``; each
    coordinate of ``z`` maps to ``u = 1/2 + atan(z / spread) / pi``. Choosing ``mean_slope`` and
    ``scale`` (``diag(alpha_x, alpha_y)``, or a Cholesky factor of a slope covariance) from the
    nominal roughness spreads an NDF-shaped lobe over the square whatever its width, anisotropy
    or view. Domains: all normals (``wo`` None); normals visible from ``wo (3,)``
    (``wo.m > 0``, a line in slope space); with ``reflect``, directions ``wi`` above the horizon
    whose half vector ``h = normalize(wo + wi)`` is warped, ``d(omega_i) = 4 (wo.h) d(omega_h)``
    (Walter et al. 2007 eq. 14), ``wi_z > 0`` being the disk ``|s + wo_xy / wo_z| < 1 / wo_z``.
    ``above (3,)`` further restricts that domain to ``wi.above > 0`` (e.g. the mean surface of
    non-centred slopes, below which a lobe vanishes). ``d(omega_h) = h_z^3 ds``. Each domain's
    edge is given to the quadrature as ``v_range``; with ``wo``, ``z`` is turned so that its
    second axis is along ``scale^T wo_xy``, and with ``reflect`` the first coordinate's range
    over the horizon disk is mapped onto all of [0, 1] (cosine-packed at both ends).
    """
    mu = as_float_array(mean_slope, "mean_slope", ndim_min=1, last_dim=2)
    S = as_float_array(scale, "scale", ndim_min=2, last_dim=2)
    if mu.shape != (2,) or S.shape != (2, 2):
        raise PrefilterError(f"mean_slope, scale: expected shapes (2,) and (2, 2), got "
                             f"{mu.shape} and {S.shape}")
    det = float(np.linalg.det(S))
    if not abs(det) > 1e-300:
        raise PrefilterError(f"scale: expected an invertible 2x2 matrix, got {S.tolist()}")
    S_inv = np.linalg.inv(S)
    spread = float(as_float_array(spread, "spread"))
    if not spread > 0.0:
        raise PrefilterError(f"spread: expected a positive number, got {spread!r}")
    if wo is not None:
        wo = as_directions(wo, "wo")
        if wo.shape != (3,) or not wo[2] > 0.0:
            raise PrefilterError(f"wo: expected one direction (3,) with z > 0, got {wo.tolist()}")
    elif reflect:
        raise PrefilterError("wo: reflect=True needs the view direction wo")
    if above is not None:
        above = as_directions(above, "above")
        if above.shape != (3,) or not reflect:
            raise PrefilterError(f"above: expected one direction (3,) with reflect=True, got "
                                 f"{above.tolist()}")
    if wo is not None:
        # Turn z so its second axis runs along S^T wo_xy: the visibility line wo.m = 0 is then
        # a row of the square (and the horizon nearly one), cut by v_range at a smooth height.
        g = S.T @ wo[:2]
        gn = np.linalg.norm(g)
        if gn > 0.0:
            gx, gy = g / gn
            S = S @ np.array([[gy, gx], [-gx, gy]])
            S_inv = np.linalg.inv(S)

    # u = 1/2 + atan(z / spread) / pi per coordinate, except z0 in reflect mode: the horizon
    # disk spans z0 in [za, zb], mapped onto all of [0, 1] through t = (1 - cos(pi u)) / 2 so
    # the chord, which vanishes like sqrt(zb - z0) at the disk's ends, is smooth in u0.
    a_lo, a_hi, packed = -np.pi / 2, np.pi / 2, False
    if reflect:
        e0, d1 = S[:, 0], S[:, 1]
        m0 = mu + wo[:2] / wo[2]
        cde = d1[0] * e0[1] - d1[1] * e0[0]
        cdm = d1[0] * m0[1] - d1[1] * m0[0]
        rd = np.linalg.norm(d1) / wo[2]
        za, zb = sorted(((-rd - cdm) / cde, (rd - cdm) / cde))
        a_lo, a_hi, packed = np.arctan(za / spread), np.arctan(zb / spread), True

    def to_u(z):
        return 0.5 + np.arctan(z / spread) / np.pi

    def to_u0(z0):
        t = np.clip((np.arctan(z0 / spread) - a_lo) / (a_hi - a_lo), 0.0, 1.0)
        return np.arccos(1.0 - 2.0 * t) / np.pi if packed else t

    def from_u0(u0):
        """``z0`` and ``dz0 / du0``."""
        t, dt = ((1.0 - np.cos(np.pi * u0)) / 2, np.pi / 2 * np.sin(np.pi * u0)) if packed \
            else (u0, 1.0)
        tn = np.tan(a_lo + (a_hi - a_lo) * t)
        return spread * tn, spread * (1.0 + tn * tn) * (a_hi - a_lo) * dt

    def to_square(w):
        h = w + wo if reflect else w
        ok = h[..., 2] > 0.0
        if reflect:
            ok &= w[..., 2] > 0.0
            if above is not None:
                ok &= w @ above > 0.0
        elif wo is not None:
            ok &= w @ wo > 0.0
        hz = np.where(ok, h[..., 2], 1.0)
        z = (-h[..., :2] / hz[..., None] - mu) @ S_inv.T
        u = np.stack([to_u0(z[..., 0]), to_u(z[..., 1])], axis=-1)
        return np.where(ok[..., None], u, np.nan)

    def from_square(u):
        z0, dz0 = from_u0(u[..., 0])
        t1 = np.tan(np.pi * (u[..., 1] - 0.5))
        s = mu + np.stack(np.broadcast_arrays(z0, spread * t1), axis=-1) @ S.T
        hz = 1.0 / np.sqrt(1.0 + np.sum(s * s, axis=-1))
        h = np.concatenate([-s * hz[..., None], hz[..., None]], axis=-1)
        jac = dz0 * spread * np.pi * (1.0 + t1 * t1) * abs(det) * hz**3
        if wo is None:
            return h, jac
        c = h @ wo
        if not reflect:
            return h, np.where(c > 0.0, jac, 0.0)
        w = 2.0 * c[..., None] * h - wo
        ok = (c > 0.0) & (w[..., 2] > 0.0)
        if above is not None:
            ok &= w @ above > 0.0
        w = np.where(ok[..., None], w, np.array([0.0, 0.0, 1.0]))
        return w, np.where(ok, 4.0 * c * jac, 0.0)

    def v_range(u0):
        # The line s = p + z1 d at fixed z0, intersected with the domain.
        p = mu + np.multiply.outer(from_u0(u0)[0], S[:, 0])
        d = S[:, 1]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if not reflect:  # wo_z - s.wo_xy > 0, linear in z1
                k = d @ wo[:2]
                f0 = wo[2] - p @ wo[:2]
                if k == 0.0:
                    full = f0 > 0.0
                    return [(np.where(full, 0.0, 0.5), np.where(full, 1.0, 0.5))]
                root = to_u(f0 / k)
                return [(np.zeros_like(root), root) if k > 0.0 else (root, np.ones_like(root))]
            # |s + b|^2 < 1 / wo_z^2 with |b|^2 - 1 / wo_z^2 = -1: a z1^2 + b_ z1 + c < 0
            b = wo[:2] / wo[2]
            a = d @ d
            b_ = 2.0 * ((p + b) @ d)
            c = np.sum(p * p, axis=-1) + 2.0 * (p @ b) - 1.0
            disc = b_ * b_ - 4.0 * a * c
            sq = np.sqrt(np.maximum(disc, 0.0))
            q = -0.5 * (b_ + np.where(b_ >= 0.0, sq, -sq))
            r1, r2 = q / a, c / q
            real = disc > 0.0
            lo = np.where(real, np.nan_to_num(np.minimum(r1, r2), nan=0.0), 0.0)
            hi = np.where(real, np.nan_to_num(np.maximum(r1, r2), nan=0.0), 0.0)
            if above is None:
                return [(to_u(lo), to_u(hi))]
            # wi.v > 0 <=> 2 (wo_z - s.wo_xy)(v_z - s.v_xy) - (wo.v)(1 + |s|^2) > 0, quadratic.
            a0, a1 = wo[2] - p @ wo[:2], d @ wo[:2]
            b0, b1 = above[2] - p @ above[:2], d @ above[:2]
            k = wo @ above
            ga = 2.0 * a1 * b1 - k * a
            gb = -2.0 * (a0 * b1 + a1 * b0) - 2.0 * k * (p @ d)
            gc = 2.0 * a0 * b0 - k * (1.0 + np.sum(p * p, axis=-1))
            gdisc = gb * gb - 4.0 * ga * gc
            gsq = np.sqrt(np.maximum(gdisc, 0.0))
            gq = -0.5 * (gb + np.where(gb >= 0.0, gsq, -gsq))
            g1, g2 = gq / ga, gc / gq
            greal = gdisc > 0.0
            glo = np.where(greal, np.nan_to_num(np.minimum(g1, g2), nan=0.0), 0.0)
            ghi = np.where(greal, np.nan_to_num(np.maximum(g1, g2), nan=0.0), 0.0)
            if ga < 0.0:  # positive between the roots (nowhere without real roots)
                return [(to_u(np.maximum(lo, glo)), to_u(np.where(greal, np.minimum(hi, ghi),
                                                                   lo)))]
            # positive outside the roots (everywhere without real roots)
            return [(to_u(lo), to_u(np.where(greal, np.minimum(hi, glo), hi))),
                    (to_u(np.where(greal, np.maximum(lo, ghi), hi)), to_u(hi))]

    return Warp(to_square, from_square, None if wo is None else v_range)
