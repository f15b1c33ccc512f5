"""Point light closed form vs Monte Carlo over the slope distribution; Smith's projected-area
identity (supplemental eq. 9) by quadrature."""

import numpy as np
import pytest

from prefilter.leadr import point_light
from prefilter.microfacet import Beckmann

CASES = [
    # mean slope, covariance, view
    ((0.0, 0.0), ((0.02, 0.0), (0.0, 0.02)), (0.3, 0.1, 0.9)),
    ((0.2, -0.1), ((0.04, 0.012), (0.012, 0.015)), (-0.4, 0.3, 0.8)),
    ((-0.3, 0.25), ((0.09, -0.03), (-0.03, 0.05)), (0.7, 0.2, 0.4)),
]


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _projected_area_quadrature(mu, cov, wo, k=96):
    """``E_s[max(0, wo.m) / m_z]`` = ``E[max(0, wo_z - s.wo_xy)]`` by 2D Gauss-Hermite."""
    x, w = np.polynomial.hermite_e.hermegauss(k)
    w = w / w.sum()
    L = np.linalg.cholesky(np.asarray(cov))
    z = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    s = np.asarray(mu) + z @ L.T
    ww = np.outer(w, w).ravel()
    return np.sum(ww * np.maximum(0.0, wo[2] - s @ wo[:2]))


@pytest.mark.parametrize("mu,cov,wo", CASES)
def test_smith_projected_area_identity_by_quadrature(mu, cov, wo):
    # integral <m, wo> D(m) dm = (1 + Lambda(wo)) (n_bar.wo / n_bar.g)  (supplemental eq. 9).
    wo = _unit(wo)
    b = Beckmann(mu, cov)
    quad = _projected_area_quadrature(mu, cov, wo)
    area = wo[2] - np.dot(mu, wo[:2])
    np.testing.assert_allclose((1.0 + b.smith_lambda(wo)) * area, quad, rtol=2e-4)


def _cone(axis, delta, k=24):
    """Gauss-Legendre nodes (directions, weights) over a cone of half-angle delta."""
    x, w = np.polynomial.legendre.leggauss(k)
    ct = 1.0 - (1.0 - np.cos(delta)) * (x + 1) / 2
    wc = w * (1.0 - np.cos(delta)) / 2
    phi = 2 * np.pi * (np.arange(2 * k) + 0.5) / (2 * k)
    st = np.sqrt(1 - ct**2)
    d = np.stack(np.broadcast_arrays(st[:, None] * np.cos(phi), st[:, None] * np.sin(phi),
                                     ct[:, None]), -1).reshape(-1, 3)
    wt = np.repeat(wc, 2 * k) * 2 * np.pi / (2 * k)
    a = _unit(axis)
    t = _unit(np.cross(a, [0.0, 0.3, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0]))
    b = np.cross(a, t)
    return d @ np.stack([t, b, a]), wt


@pytest.mark.parametrize("mu,cov,wo", CASES)
@pytest.mark.parametrize("shadowing", [True, False])
def test_point_light_equals_monte_carlo_over_slopes(mu, cov, wo, shadowing):
    """A small cone light of unit total 'irradiance' seen through the microsurface: Monte Carlo
    over slopes s ~ N(mu, Sigma), each facet mirroring wo with projected-area weight
    max(0, wo.m)/m_z and Smith G2, normalised by the mesosurface's projected area. The closed
    form is integrated over the same cone by quadrature."""
    wo = _unit(wo)
    rng = np.random.default_rng(11)
    b = Beckmann(mu, cov)
    wl = _unit(2.0 * np.dot(_unit([-np.asarray(mu)[0], -np.asarray(mu)[1], 1]), wo)
               * _unit([-np.asarray(mu)[0], -np.asarray(mu)[1], 1]) - wo + [0.05, -0.04, 0.0])
    delta = 0.12
    dirs, wts = _cone(wl, delta)
    omega = 2 * np.pi * (1 - np.cos(delta))
    ref = np.sum(wts * point_light(wo, dirs, mu, cov, shadowing=shadowing)) / omega
    area = wo[2] - np.dot(mu, wo[:2])
    n, vals = 400_000, []
    L = np.linalg.cholesky(np.asarray(cov))
    for _ in range(1):
        s = np.asarray(mu) + rng.normal(size=(n, 2)) @ L.T
        m = np.concatenate([-s, np.ones((n, 1))], 1)
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        dot = m @ wo
        wi = 2 * dot[:, None] * m - wo
        hit = (wi @ wl > np.cos(delta)) & (dot > 0)
        g = np.zeros(n)
        lam_i = b.smith_lambda(wi[hit]) if shadowing else 0.0
        g[hit] = 1.0 / (1.0 + b.smith_lambda(wo) + lam_i)
        vals.append(np.maximum(dot, 0) / m[:, 2] * g / (omega * area))
    vals = np.concatenate(vals)
    est, err = vals.mean(), vals.std() / np.sqrt(vals.size)
    assert abs(est - ref) < 4 * err + 1e-3 * ref, (est, ref, err)


def test_fresnel_and_walter_fit():
    mu, cov = (0.1, 0.05), ((0.03, 0.0), (0.0, 0.03))
    wo, wi = _unit([0.2, 0.1, 1.0]), _unit([-0.1, 0.0, 1.0])
    h = _unit(wo + wi)
    base = point_light(wo, wi, mu, cov)
    f = point_light(wo, wi, mu, cov, f0=0.04)
    np.testing.assert_allclose(f / base, 0.04 + 0.96 * (1 - h @ wi) ** 5, rtol=1e-12)
    # Walter's fit of Lambda changes G2 by less than 1% (max |dG1| 3.1e-3 over a in (0, 3]).
    wo_g = _unit([0.9, 0.0, 0.25])
    r = point_light(wo_g, wi, mu, cov, lambda_fit="walter") / point_light(wo_g, wi, mu, cov)
    assert abs(r - 1) < 0.01


def test_no_nan_for_grazing_or_backfacing_views():
    mu, cov = (0.6, -0.2), ((0.05, 0.0), (0.0, 0.05))
    wo = np.array([_unit([1, 0, 0]), _unit([1, 0, -0.3]), [0, 0, -1.0], _unit([-1, 0, 0.2])])
    v = point_light(wo, _unit([0, 0.2, 1]), mu, cov)
    assert np.all(np.isfinite(v)) and np.all(v >= 0)
