"""Acceptance machinery: random configurations, the MIS reference and the error statistics."""

import json

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.ltc import LTC
from prefilter.sphere.polygon import polygon_integral
from prefilter.ltc.validate import (
    clip_to_horizon,
    error_statistics,
    format_statistics,
    random_configurations,
    reference_quad_integral,
)
from prefilter.microfacet import GGX

# measured on the shipped table by `prefilter validate` (docs/ltc.md), plus a small margin
ACCEPT_MEDIAN_MEASURED = 0.035
ACCEPT_P90_MEASURED = 0.30


def _quadrature(model, wo, quad, k=1000):
    """Midpoint rule over the parallelogram ``quad`` in area measure: f |cos_l| / r^2 dA."""
    c = quad.mean(0)
    a = (quad[1] - quad[0]) / 2
    b = (quad[3] - quad[0]) / 2
    s = (np.arange(k) + 0.5) / k * 2 - 1
    S, T = np.meshgrid(s, s, indexing="ij")
    p = c + S[..., None] * a + T[..., None] * b
    r = np.linalg.norm(p, axis=-1)
    w = p / r[..., None]
    n = np.cross(a, b)
    dA = np.linalg.norm(n) * (2 / k) ** 2
    n /= np.linalg.norm(n)
    f = model.eval(wo, w.reshape(-1, 3)).reshape(k, k)
    return float(np.sum(f * np.abs(w @ n) / r**2) * dA)


def test_configurations_are_front_facing_and_straddle_as_stated():
    cfg = random_configurations(400, 3, straddle_fraction=0.25)
    q = cfg["quad"]
    normal = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    # counter-clockwise seen from the shading point: right-hand normal points at the origin
    assert np.all(np.sum(normal * q[:, 0], -1) < 0)
    below = (q[..., 2] <= 0).sum(-1)
    assert np.all((below > 0) & (below < 4) == cfg["straddle"])
    assert cfg["straddle"].sum() == 100
    theta = np.degrees(np.arccos(cfg["wo"][:, 2]))
    assert theta.max() <= 85 and theta.min() >= 0
    assert cfg["alpha"].min() >= 0.05 and cfg["alpha"].max() <= 1.0
    # planar parallelograms
    assert np.allclose(q[:, 0] + q[:, 2], q[:, 1] + q[:, 3])


def test_configurations_deterministic():
    a = random_configurations(50, 7)
    b = random_configurations(50, 7)
    for k in a:
        assert np.array_equal(a[k], b[k])


@pytest.mark.parametrize(
    "theta, alpha, cfg_index",
    [(0.3, 0.4, 0), (1.2, 0.25, 1), (0.9, 0.6, 2)],
)
def test_reference_matches_area_quadrature(theta, alpha, cfg_index):
    rng = np.random.default_rng(11)
    cfg = random_configurations(8, 5, straddle_fraction=0.5)
    quad = cfg["quad"][cfg_index]
    wo = np.array([np.sin(theta), 0.0, np.cos(theta)])
    model = GGX(alpha)
    est, se = reference_quad_integral(model, wo, quad, 100_000, rng)
    ref = _quadrature(model, wo, quad)
    assert ref > 1e-3
    assert se < 0.02 * ref
    assert abs(est - ref) < 4 * se + 2e-3 * ref


def test_reference_lobe_inside_quad():
    # a large quad around the reflection direction catches most of a narrow lobe
    theta = 0.5
    wo = np.array([np.sin(theta), 0.0, np.cos(theta)])
    r = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    e1 = np.array([0.0, 1.0, 0.0])
    e2 = np.cross(r, e1)
    c = 2 * r
    quad = np.stack([c - e1 - e2, c - e1 + e2, c + e1 + e2, c + e1 - e2])
    model = GGX(0.05)
    est, se = reference_quad_integral(model, wo, quad, 100_000, np.random.default_rng(0))
    ref = _quadrature(model, wo, quad, k=1500)
    assert abs(est - ref) < 4 * se + 2e-3 * ref
    assert ref < float(model.albedo(wo))


def test_reference_rejects_bad_input():
    model = GGX(0.3)
    quad = np.array([[0, 0, 1.0], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    with pytest.raises(PrefilterError, match="wo"):
        reference_quad_integral(model, [0, 0, -1.0], quad, 100, 0)
    with pytest.raises(PrefilterError, match="n_samples"):
        reference_quad_integral(model, [0, 0, 1.0], quad, 0, 0)
    with pytest.raises(PrefilterError, match="quad"):
        reference_quad_integral(model, [0, 0, 1.0], np.zeros((4, 3)), 100, 0)
    with pytest.raises(PrefilterError, match="rng"):
        reference_quad_integral(model, [0, 0, 1.0], quad, 100, None)


def test_error_statistics_known_values():
    ref = np.array([1.0, 1.0, 1.0, 1.0, 1e-5])
    est = np.array([1.01, 0.98, 1.05, 1.2, 0.0])
    theta = np.radians([10.0, 30.0, 50.0, 80.0, 10.0])
    alpha = np.array([0.06, 0.15, 0.3, 0.9, 0.5])
    s = error_statistics(est, ref, theta, alpha, albedo=np.full(5, 2.0))
    assert [b["count"] for b in s["by_fraction"]] == [0, 0, 0, 0, 4]
    assert s["count"] == 4 and s["excluded"] == 1
    assert s["median"] == pytest.approx(np.median([0.01, 0.02, 0.05, 0.2]))
    assert s["p90"] == pytest.approx(np.percentile([0.01, 0.02, 0.05, 0.2], 90))
    assert s["excluded_max_abs"] == pytest.approx(1e-5)
    assert [b["count"] for b in s["by_theta"]] == [1, 1, 1, 0, 1]
    assert s["by_theta"][4]["median"] == pytest.approx(0.2)
    assert [b["count"] for b in s["by_alpha"]] == [1, 1, 1, 0, 1]
    json.dumps(s)
    assert "median" in format_statistics(s)


def test_clip_to_horizon_square():
    # square in the plane x = 1 spanning z in [-1, 1]: the clipped part is z in [0, 1]
    sq = np.array([[1.0, -1, -1], [1, 1, -1], [1, 1, 1], [1, -1, 1]])
    c = clip_to_horizon(sq)
    assert c.shape == (5, 3)
    assert np.all(c[:, 2] >= 0)
    corners = {tuple(v) for v in np.round(c, 12)}
    assert corners == {(1, 1, 0), (1, 1, 1), (1, -1, 1), (1, -1, 0)}
    assert np.all(clip_to_horizon(sq - [0, 0, 3]) == 0)
    assert np.allclose(clip_to_horizon(sq + [0, 0, 3])[:4], sq + [0, 0, 3])


def test_clipped_ltc_integral_matches_ltc_monte_carlo():
    """LTC mass on the part of a straddling quad above the surface, vs sampling the LTC."""
    M = np.array([[0.45, 0.0, -0.5], [0.0, 0.5, 0.0], [0.25, 0.0, 0.6]])
    cfg = random_configurations(30, 1, straddle_fraction=1.0)
    rng = np.random.default_rng(2)
    w = LTC(M).sample(rng.random((400_000, 2)))
    for q in cfg["quad"][:5]:
        nq = np.cross(q[1] - q[0], q[2] - q[0])
        t = (nq @ q[0]) / (w @ nq)
        p = t[:, None] * w
        inside = (t > 0) & (w[:, 2] > 0)
        for k in range(4):
            inside &= (np.cross(q[(k + 1) % 4] - q[k], p - q[k]) @ nq) >= 0
        mc = inside.mean()
        got = polygon_integral(M, clip_to_horizon(q))
        assert abs(got - mc) < 4 * np.sqrt(mc * (1 - mc) / len(w)) + 1e-4


@pytest.fixture(scope="module")
def acceptance():
    from prefilter.ltc import GGXTable
    from prefilter.ltc.validate import run_acceptance

    return run_acceptance(GGXTable.load(), 2000, 100_000, 0)["stats"]


@pytest.mark.slow
def test_acceptance_no_regression(acceptance):
    """2000 configurations, 1e5 MC samples each: the shipped table's measured level."""
    assert acceptance["count"] >= 1700
    assert acceptance["median"] <= ACCEPT_MEDIAN_MEASURED
    assert acceptance["p90"] <= ACCEPT_P90_MEASURED


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue target p90 <= 10 % is not met: a single LTC cannot "
                   "follow GGX's tails, quads catching < 3 % of the lobe dominate (docs/ltc.md)")
def test_acceptance_issue_targets(acceptance):
    assert acceptance["median"] <= 0.03
    assert acceptance["p90"] <= 0.10
