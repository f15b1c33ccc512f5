"""Fitting the isotropic GGX LTC: lobe moments, single fits, resumable bakes and the CLI."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from prefilter.cli import cli
from prefilter.ltc import LTC, GGXTable
from prefilter.errors import PrefilterError
from prefilter.ltc.fit_iso import (
    FitSettings,
    ProbeSettings,
    bake_table,
    fit_entry,
    lobe_moments,
    ltc_from_params,
    normalize_ltc,
    params_from_ltc,
    probe_quads,
    probe_references,
    refine_entry,
    view_from_t,
)
from prefilter.sphere.polygon import polygon_integral
from prefilter.ltc.validate import clip_to_horizon, random_quads, reference_quad_integral
from prefilter.microfacet import GGX, reflect
from prefilter.sphere.sampling import uniform_sphere

TINY = dict(res_theta=3, res_alpha=3, n_fit=6, quad_nodes=16, seed=1)


def _view(theta):
    return np.array([np.sin(theta), 0.0, np.cos(theta)])


def _l1_distance(wo, alpha, M, n=200_000, seed=0):
    """MC estimate of integral |lobe / albedo - LTC| (balance heuristic, lobe + LTC samples)."""
    rng = np.random.default_rng(seed)
    g, L = GGX(alpha), LTC(M)
    wb = reflect(wo, g.sample_vndf(wo, rng.random((n, 2))))
    wl = L.sample(rng.random((n, 2)))
    w = np.concatenate([wb, wl])
    p = g.eval(wo, w) / g.albedo(wo)
    q = L.eval(w)
    return float(np.sum(np.abs(p - q) / (g.pdf_reflect(wo, w) + q)) / n)


@pytest.mark.parametrize("theta_deg, alpha", [(0, 1.0), (30, 0.6), (60, 0.4), (80, 0.8)])
def test_lobe_moments_vs_uniform_monte_carlo(theta_deg, alpha):
    wo = _view(np.radians(theta_deg))
    w = uniform_sphere(np.random.default_rng(theta_deg).random((1_000_000, 2)))
    f = GGX(alpha).eval(wo, w) * 4 * np.pi
    h = (w + wo) / np.linalg.norm(w + wo, axis=-1, keepdims=True)
    f5 = f * (1 - np.sum(w * h, -1)) ** 5
    fd = f[:, None] * w
    mom = lobe_moments(wo, alpha)
    for got, x in [(mom["magnitude"], f), (mom["fresnel"], f5)]:
        assert abs(got - x.mean()) < 4 * x.std() / 1000 + 1e-6
    d = fd.mean(0)
    se = fd.std(0) / 1000
    d_n = np.linalg.norm(d)
    assert np.all(np.abs(mom["direction"] * d_n - d) < 4 * se + 1e-3 * d_n)


@pytest.mark.parametrize("theta_deg, alpha", [(40, 0.02), (85, 0.05)])
def test_lobe_moments_vs_vndf_monte_carlo_smooth(theta_deg, alpha):
    # smooth lobes: random visible normals, n = E[G2/G1], f5 = E[G2/G1 (1 - wo.m)^5]
    wo = _view(np.radians(theta_deg))
    g = GGX(alpha)
    k = 500_000
    m = g.sample_vndf(wo, np.random.default_rng(2).random((k, 2)))
    wi = reflect(wo, m)
    wgt = np.where(wi[:, 2] > 0, g.G2(wo, wi) / g.G1(wo), 0.0)
    mom = lobe_moments(wo, alpha)
    for got, x in [(mom["magnitude"], wgt), (mom["fresnel"], wgt * (1 - m @ wo) ** 5)]:
        assert abs(got - x.mean()) < 4 * x.std() / np.sqrt(k) + 1e-6


def test_ltc_from_params_form():
    M = ltc_from_params(np.array([np.log(0.3), np.log(0.5), 0.2, -0.4]))
    assert M[0, 1] == M[1, 0] == M[1, 2] == M[2, 1] == 0.0
    assert M[1, 1] == pytest.approx(0.5)
    assert np.linalg.det(M) > 0
    # without skew the third column is the frame's z axis (sin beta, 0, cos beta)
    M0 = ltc_from_params(np.array([0.0, 0.0, 0.0, -0.4]))
    assert np.allclose(M0[:, 2], [np.sin(-0.4), 0, np.cos(-0.4)])


def test_fit_normal_view_is_isotropic_and_close():
    fit = fit_entry(0.0, 0.2)
    M = fit["M"]
    assert np.allclose(M, np.diag(np.diag(M)), atol=1e-15)
    assert M[0, 0] == pytest.approx(M[1, 1])
    assert _l1_distance(_view(0.0), 0.2, M) < 0.05


@pytest.mark.parametrize("theta_deg, alpha, bound", [(45, 0.3, 0.12), (30, 0.05, 0.1)])
def test_fresh_fit_matches_lobe(theta_deg, alpha, bound):
    """L1 distance between the normalised lobe and the fitted LTC, by Monte Carlo."""
    theta = np.radians(theta_deg)
    fit = fit_entry(theta, alpha)
    wo = _view(theta)
    assert _l1_distance(wo, alpha, fit["M"]) < bound
    # and shading with quads that catch >= 10 % of the lobe (the LTC's tails are not GGX's, so
    # quads catching only a few percent can be off by 10-30 %; see docs/ltc.md)
    rng = np.random.default_rng(4)
    quads = random_quads(16, rng)
    est = fit["magnitude"] * polygon_integral(fit["M"], clip_to_horizon(quads))
    ref = np.array([reference_quad_integral(GGX(alpha), wo, q, 40_000, rng)[0] for q in quads])
    keep = ref > 0.1 * fit["magnitude"]
    rel = np.abs(est - ref)[keep] / ref[keep]
    assert keep.sum() >= 2 and rel.max() < 0.06


def test_fit_is_deterministic():
    a = fit_entry(0.7, 0.4, n_fit=12)
    b = fit_entry(0.7, 0.4, n_fit=12)
    assert np.array_equal(a["M"], b["M"])


def test_view_from_t():
    assert np.allclose(view_from_t(0.0), [0, 0, 1])
    t = np.sqrt(1 - np.cos(0.9))
    assert np.allclose(view_from_t(t), _view(0.9))


class _Stop(Exception):
    pass


def test_bake_resumes_to_identical_bytes(tmp_path):
    settings = FitSettings(**TINY)
    full = bake_table(tmp_path / "full.npz", settings, progress=False)

    out = tmp_path / "resumed.npz"
    done = []

    def stop_after_two(i):
        done.append(i)
        if len(done) == 2:
            raise _Stop

    with pytest.raises(_Stop):
        bake_table(out, settings, progress=False, on_row=stop_after_two)
    assert not out.exists()
    parts = sorted(p.name for p in (tmp_path / "resumed.npz.parts").glob("0*.npz"))
    assert parts == ["000000.npz", "000001.npz"]
    seen = []
    bake_table(out, settings, progress=False, on_row=seen.append)
    assert seen == [2]  # only the missing row was fitted
    assert out.read_bytes() == full.read_bytes()
    assert not (tmp_path / "resumed.npz.parts").exists()
    table = GGXTable.load(out)
    assert table.M.shape == (3, 3, 3, 3)


def test_bake_parts_from_other_settings_are_discarded(tmp_path):
    out = tmp_path / "t.npz"

    def stop(i):
        raise _Stop

    with pytest.raises(_Stop):
        bake_table(out, FitSettings(**{**TINY, "seed": 5}), progress=False, on_row=stop)
    seen = []
    bake_table(out, FitSettings(**TINY), progress=False, on_row=seen.append)
    assert seen == [0, 1, 2]


def test_cli_bake_and_validate(tmp_path):
    runner = CliRunner()
    out = tmp_path / "tiny.npz"
    r = runner.invoke(cli, ["bake", "ltc-iso", "--res", "3", "--samples", "6", "--seed", "2",
                            "-o", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    table = GGXTable.load(out)
    assert table.M.shape == (3, 3, 3, 3)
    js = tmp_path / "stats.json"
    r = runner.invoke(cli, ["validate", "--table", str(out), "--configs", "6", "--samples", "2000",
                            "--json", str(js), "--quiet"])
    assert r.exit_code == 0, r.output
    assert "median" in r.output
    stats = json.loads(js.read_text())
    assert stats["count"] + stats["excluded"] == 6


# --- probe-light refit (experimental second stage, not used by the bake) -----------------------


def test_params_from_ltc_inverts_ltc_from_params():
    rng = np.random.default_rng(4)
    for _ in range(20):
        p = np.array([rng.uniform(-3, 0.5), rng.uniform(-3, 0.5), rng.uniform(-1, 1),
                      rng.uniform(-1.2, 1.2)])
        M = 2.7 * ltc_from_params(p)  # the table stores M up to scale
        assert np.allclose(params_from_ltc(M), p, atol=1e-10)


def test_probe_quads_front_facing_and_never_acceptance_seed():
    wo = _view(np.radians(70))
    s = ProbeSettings(probes_random=40, probes_lobe=20, seed=3)
    q = probe_quads(wo, 0.2, s)
    assert q.shape == (60, 4, 3)
    # counter-clockwise seen from the origin: the (unclipped) form factor is positive
    assert np.all(polygon_integral(np.eye(3), clip_to_horizon(q)) > 0)
    assert np.all(polygon_integral(np.eye(3), clip_to_horizon(q[:, ::-1])) == 0)
    assert ((q[:40, :, 2] <= 0).any(1)).sum() == 8  # 20 % straddle the horizon
    # lobe probes catch far more of the lobe than random ones
    ref = probe_references(wo, 0.2, q, 2048, 256, 0)
    assert np.median(ref[40:]) > 5 * np.median(ref[:40])
    with pytest.raises(PrefilterError, match="seed"):
        probe_quads(wo, 0.2, ProbeSettings(seed=0))


@pytest.mark.parametrize("theta_deg, alpha", [(20, 0.5), (75, 0.15)])
def test_probe_references_match_mis_reference(theta_deg, alpha):
    """The vectorised estimator agrees with ``validate.reference_quad_integral`` (4 sigma)."""
    wo = _view(np.radians(theta_deg))
    q = probe_quads(wo, alpha, ProbeSettings(probes_random=5, probes_lobe=3, seed=7))
    runs = np.array([probe_references(wo, alpha, q, 2048, 256, s) for s in range(30)])
    mean, se = runs.mean(0), runs.std(0, ddof=1) / np.sqrt(len(runs))
    rng = np.random.default_rng(11)
    for k in range(len(q)):
        ref, ref_se = reference_quad_integral(GGX(alpha), wo, q[k], 100_000, rng)
        assert abs(mean[k] - ref) < 4 * np.hypot(se[k], ref_se) + 1e-6


def test_refine_entry_repairs_a_perturbed_fit():
    """From a deliberately wrong start, the probe refit lowers the error on independent quads."""
    theta, alpha = np.radians(45), 0.3
    wo = _view(theta)
    fit = fit_entry(theta, alpha, n_fit=12, quad_nodes=32)
    p = fit["params"] + np.array([0.4, -0.3, 0.0, 0.0])
    bad = normalize_ltc(ltc_from_params(p))
    out = refine_entry(wo, alpha, bad, fit["magnitude"], ProbeSettings(seed=5))
    assert out["error"] < out["error_start"]
    # independent test quads (other seed), references by the validate estimator
    rng = np.random.default_rng(21)
    qs = probe_quads(wo, alpha, ProbeSettings(probes_random=12, probes_lobe=12, seed=9))
    ref = np.array([reference_quad_integral(GGX(alpha), wo, q, 20_000, rng)[0] for q in qs])
    err = [np.median(np.abs(fit["magnitude"] * polygon_integral(M, clip_to_horizon(qs)) - ref)
                     / ref) for M in (bad, out["M"])]
    assert err[1] < 0.5 * err[0]
