"""Every lobe through the one interface (:class:`prefilter.lobe.Lobe`): its sampler against its
pdf by a chi-square test, ``weight == eval / pdf`` at the draws, the pdf's integral by quadrature,
``E[weight] == albedo``, and a pdf 5 % off rejected by the same test.

Bins: microfacet lobes (GGX, Beckmann, LEADR) and LTC lobes (through the GGX they fit) in the
slope space of the half vector (:func:`prefilter.sphere.slope_warp`), which stays sharp for
narrow grazing lobes; glint lobes in a cap around pilot draws, restricted to the upper
hemisphere. Draws below the horizon (weight 0, or failed) join the outside bin. Glint lobes
are sums of narrow element Gaussians (intrinsic roughness 0.005): the fast cases use a small
footprint (1.5 texels, ~40 elements), wide ones (6 texels) are slow cases; their bins'
quadrature is coarser (see :func:`chi2`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.glints import surface
from prefilter.glints.lobe import GlintLobe
from prefilter.leadr.lobe import LeadrLobe
from prefilter.leadr.shading import point_light
from prefilter.lobe import Lobe, sample_weight
from prefilter.ltc.aniso import AnisoGGXTable
from prefilter.ltc.lobe import LTCLobe
from prefilter.ltc.table import GGXTable
from prefilter.microfacet import GGX, Beckmann, MicrofacetModel
from prefilter.multiscale.lobe import MultiscaleLobe
from prefilter.sphere import chi2_sphere, chi2_warped, lobe_cap, spherical_direction
from prefilter.texture.procedural import normal_map

sys.path.insert(0, str(Path(__file__).parent / "microfacet"))
from mf_quad import reflect_integral, reflect_warp, sphere_integral  # noqa: E402

N_SAMPLES = 200_000


def view(theta_deg, phi_deg=40.0):
    return spherical_direction(np.radians(theta_deg), np.radians(phi_deg))


def _glint_surface(intrinsic_roughness=None):
    # a direct-only surface: no bake; every footprint is the Yan et al. 2016 P-NDF of the map
    return surface(None, normal_map("gaussian", 64, seed=1),
                   intrinsic_roughness=intrinsic_roughness)


def _total_off(alpha_micro, r, **variants):
    """The LTC lobe at the multi-scale lobe's total roughness 5 % off."""
    return LTCLobe(1.05 * MultiscaleLobe(alpha_micro, r, **variants).alpha_x)


_COV = [[0.05, 0.02], [0.02, 0.01]]
_LEADR_COV = [[0.04, 0.01], [0.01, 0.02]]

# id -> (lobe factory, the same lobe 5 % off (roughness, or the footprint), view angle in deg)
CASES = {
    "ggx-0.02-3": (lambda: GGX(0.02), lambda: GGX(0.021), 3),
    "ggx-aniso-85": (lambda: GGX(1.0, 0.05), lambda: GGX(1.05, 0.0525), 85),
    "ggx-0.3-0.6-89": (lambda: GGX(0.3, 0.6), lambda: GGX(0.315, 0.63), 89),
    "beckmann-iso-80": (lambda: Beckmann.isotropic(0.5), lambda: Beckmann.isotropic(0.525), 80),
    "beckmann-noncentred-69": (lambda: Beckmann([0.2, -0.1], _COV),
                               lambda: Beckmann([0.2, -0.1], np.multiply(_COV, 1.1025)), 69),
    "beckmann-aniso-mean-10": (lambda: Beckmann.anisotropic(0.02, 0.4, (0.3, -0.2)),
                               lambda: Beckmann.anisotropic(0.021, 0.42, (0.3, -0.2)), 10),
    "ltc-0.1-30": (lambda: LTCLobe(0.1), lambda: LTCLobe(0.105), 30),
    "ltc-0.5-85": (lambda: LTCLobe(0.5), lambda: LTCLobe(0.525), 85),
    "ltc-f0-60": (lambda: LTCLobe(0.3, f0=0.04), lambda: LTCLobe(0.315, f0=0.04), 60),
    "ltc-aniso-60": (lambda: LTCLobe(0.4, 0.1, table=AnisoGGXTable.load()),
                     lambda: LTCLobe(0.42, 0.105, table=AnisoGGXTable.load()), 60),
    "multiscale-45": (lambda: MultiscaleLobe(0.1, 0.95), lambda: _total_off(0.1, 0.95), 45),
    "multiscale-paper-85": (lambda: MultiscaleLobe(0.3, 0.8, meso="paper", total="paper"),
                            lambda: _total_off(0.3, 0.8, meso="paper", total="paper"), 85),
    "leadr-60": (lambda: LeadrLobe([0.2, -0.1], _LEADR_COV),
                 lambda: LeadrLobe([0.2, -0.1], np.multiply(_LEADR_COV, 1.1025)), 60),
    "leadr-f0-walter-85": (lambda: LeadrLobe([0.1, 0.3], _LEADR_COV, f0=0.04,
                                             lambda_fit="walter"),
                           lambda: LeadrLobe([0.1, 0.3], np.multiply(_LEADR_COV, 1.1025),
                                             f0=0.04, lambda_fit="walter"), 85),
    "glint-1.5-30": (lambda: GlintLobe(_glint_surface(), (20.3, 33.7), 1.5),
                     lambda: GlintLobe(_glint_surface(), (20.3, 33.7), 1.575), 30),
    "glint-1.5-75": (lambda: GlintLobe(_glint_surface(), (40.6, 9.2), 1.5, f0=0.04),
                     lambda: GlintLobe(_glint_surface(), (40.6, 9.2), 1.575, f0=0.04), 75),
}

# Cases whose checks (or rejection) take several seconds: slow only.
SLOW_CHECK = {"ggx-aniso-85", "beckmann-iso-80", "ltc-0.1-30", "glint-1.5-30"}
SLOW_REJECT = {"ggx-0.3-0.6-89", "beckmann-iso-80", "ltc-f0-60", "ltc-aniso-60", "multiscale-45",
               "glint-1.5-30"}


def _params(slow):
    return [pytest.param(c, marks=pytest.mark.slow) if c in slow else c for c in CASES]


SLOW_CASES = {
    **{f"ggx-{a}-{r}-{t}": (lambda a=a, r=r: GGX(a, a * r), None, t)
       for a in (0.02, 0.2, 1.0) for r in (1.0, 0.3) for t in (0, 45, 80, 89)},
    **{f"ltc-{a}-{t}": (lambda a=a: LTCLobe(a), None, t)
       for a in (0.02, 0.1, 0.4, 1.0) for t in (0, 45, 80, 89)},
    **{f"ltc-aniso-{a}-{t}": (lambda a=a: LTCLobe(a, 0.3 * a, table=AnisoGGXTable.load()), None,
                              t) for a in (0.1, 0.6) for t in (0, 45, 89)},
    **{f"multiscale-{a}-{r}-{t}": (lambda a=a, r=r: MultiscaleLobe(a, r), None, t)
       for a in (0.05, 0.5) for r in (0.99, 0.8) for t in (20, 80)},
    **{f"beckmann-{a}-{r}-{mu}-{t}": (
        lambda a=a, r=r, mu=mu: Beckmann.anisotropic(a, a * r, mu), None, t)
       for a in (0.02, 0.3) for r in (1.0, 0.05) for mu in ((0.0, 0.0), (0.2, 0.3))
       for t in (0, 45, 89)},
    **{f"leadr-{k}-{t}": (lambda m=m: LeadrLobe.from_moments(m, 0.1), None, t)
       for k, m in enumerate(([0.1, -0.1, 0.05, 0.04, 0.0], [0.4, 0.0, 0.2, 0.01, 0.0]))
       for t in (0, 50, 85)},
    **{f"glint-{sp}-{t}": (lambda sp=sp: GlintLobe(_glint_surface(), (12.5, 50.5), sp), None, t)
       for sp in (0.5, 6.0) for t in (10, 60, 85)},
}


def _model(lobe):
    """The microfacet model whose reflected visible normals a lobe draws, if any."""
    if isinstance(lobe, MicrofacetModel):
        return lobe
    return lobe.model if isinstance(lobe, LeadrLobe) else None


def _bins_model(lobe):
    """The microfacet model whose slope warp bins ``lobe``'s draws: its own, the GGX an LTC
    lobe fits (a narrow grazing LTC lobe is a sliver no cap resolves), none for glints."""
    if isinstance(lobe, LTCLobe):
        ax = float(lobe.alpha_x)
        return GGX(ax, ax if lobe.alpha_y is None else float(lobe.alpha_y))
    return _model(lobe)


#: Slope warp spreading a glint lobe of the test map (rms slope 0.3) for its pdf's integral.
GLINT_SPREAD = GGX(0.3)


def draw(lobe: Lobe, wo, n, seed):
    u = np.random.default_rng(seed).random((n, lobe.n_uniforms))
    return lobe.sample(wo, u)


def chi2(lobe, wo, wi, pdf_lobe=None):
    """Chi-square test of draws ``wi`` of ``lobe`` against ``pdf_lobe.pdf`` (default: its own)."""
    pdf_lobe = lobe if pdf_lobe is None else pdf_lobe
    density = lambda w: pdf_lobe.pdf(wo, w)  # noqa: E731
    model = _bins_model(lobe)
    if model is not None:
        return chi2_warped(wi, density, reflect_warp(model, wo))
    pilot = draw(lobe, wo, 20_000, 99)[0]
    axis, theta_max = lobe_cap(pilot[pilot[:, 2] > 0.0])
    # A glint pdf is a sum of narrow peaks: with its default depth the bins' adaptive
    # quadrature splits cells holding draws between its nodes 8 times (1e7 pdf evaluations,
    # 30 s); 5 splits of 4 x 4 nodes give the same p-values to 3 digits in 1 s.
    return chi2_sphere(wi, density, axis=axis, theta_max=theta_max, above=(0.0, 0.0, 1.0),
                       quad=4, max_refine=5)


def check_lobe(lobe, wo, n, seed=3):
    """All checks of one lobe at one view; returns the chi-square result."""
    wi, weight = draw(lobe, wo, n, seed)
    assert wi.shape == (n, 3) and weight.shape == (n,)
    np.testing.assert_allclose(np.linalg.norm(wi, axis=-1), 1.0, atol=1e-12)
    # (b) the weight is eval / pdf at the draws, 0 where the pdf is
    ev, pdf = lobe.eval(wo, wi), lobe.pdf(wo, wi)
    assert np.all(np.isfinite(weight) & (weight >= 0.0))
    np.testing.assert_allclose(weight, sample_weight(ev, pdf), rtol=1e-12, atol=1e-300)
    assert np.all(weight[pdf == 0.0] == 0.0)
    # (a) the draws follow the pdf
    res = chi2(lobe, wo, wi)
    assert res.passed(), res
    # (c) the pdf integrates to the fraction of draws it accounts for (1 unless draws fail)
    ok = wi[pdf > 0.0]
    if _model(lobe) is not None or isinstance(lobe, GlintLobe):
        # over the half vectors, spread by the lobe's own slopes (the map's for glints)
        model = GLINT_SPREAD if isinstance(lobe, GlintLobe) else _model(lobe)
        mass = reflect_integral(lambda w: lobe.pdf(wo, w), model, wo)
    else:
        axis = ok.mean(axis=0)
        axis /= np.linalg.norm(axis)
        width = float(np.clip(np.median(np.arccos(np.clip(ok @ axis, -1, 1))), 0.01, 1.0))
        mass = sphere_integral(lambda w: lobe.pdf(wo, w), axis=axis, width=width)
    found = ok.shape[0] / n
    assert mass <= 1.0 + 1e-3
    assert abs(mass - found) <= 4.0 * np.sqrt(found * (1.0 - found) / n) + 1e-3, (mass, found)
    # (d) E[weight] is the albedo, where the lobe has one
    try:
        albedo = float(lobe.albedo(wo))
    except NotImplementedError:
        albedo = None
    if albedo is not None:
        assert abs(weight.mean() - albedo) <= 5.0 * weight.std() / np.sqrt(n) + 1e-5, \
            (weight.mean(), albedo)
    return res


@pytest.mark.parametrize("case", _params(SLOW_CHECK))
def test_lobe(case):
    make, _, theta = CASES[case]
    res = check_lobe(make(), view(theta), N_SAMPLES)
    print(f"{case}: p = {res.p_value:.3g} (dof {res.dof})")


@pytest.mark.parametrize("case", _params(SLOW_REJECT))
def test_lobe_pdf_5_percent_off_is_rejected(case):
    make, wrong, theta = CASES[case]
    wo = view(theta)
    lobe = make()
    res = chi2(lobe, wo, draw(lobe, wo, N_SAMPLES, 3)[0], pdf_lobe=wrong())
    print(f"{case}: p = {res.p_value:.3g} (dof {res.dof})")
    assert res.p_value < 1e-6, res


@pytest.mark.slow
@pytest.mark.parametrize("case", list(SLOW_CASES))
def test_lobe_grid(case):
    make, _, theta = SLOW_CASES[case]
    lobe = make()
    wo = view(theta, 110.0)
    if _model(lobe) is not None and float(_model(lobe).G1(wo)) == 0.0:
        pytest.skip("view below the mean surface: empty lobe")
    # glint pdfs cost ~10 us a point (a walk over the footprint's texels): fewer draws
    res = check_lobe(lobe, wo, 200_000 if isinstance(lobe, GlintLobe) else 500_000, seed=13)
    print(f"{case}: p = {res.p_value:.3g} (dof {res.dof})")


def test_ltc_lobe_is_the_table_fit():
    # eval = n D_M with the table's lookup; the isotropic and anisotropic tables agree roughly
    table = GGXTable.load()
    wo, wi = view(50), view(30, 200)
    M, mag, _ = table.lookup(wo, 0.3)
    from prefilter.ltc import LTC

    assert LTCLobe(0.3, table=table).eval(wo, wi) == pytest.approx(mag * LTC(M).eval(wi))
    aniso = LTCLobe(0.3, table=AnisoGGXTable.load())
    assert aniso.albedo(wo) == pytest.approx(mag, rel=0.02)
    # views at or below the horizon: an empty lobe
    below = np.array([0.6, 0.0, -0.8])
    assert LTCLobe(0.3).eval(below, wi) == 0.0 and LTCLobe(0.3).pdf(below, wi) == 0.0
    assert LTCLobe(0.3).sample(below, [0.3, 0.6])[1] == 0.0
    with pytest.raises(PrefilterError, match="AnisoGGXTable"):
        LTCLobe(0.3, 0.1)


def test_multiscale_lobe_is_the_ltc_lobe_at_alpha_total():
    from prefilter.multiscale import alpha_meso, alpha_total

    wo, wi = view(60), view(40, 230)
    a = float(alpha_total(0.2, alpha_meso(0.9)))
    assert MultiscaleLobe(0.2, 0.9).eval(wo, wi) == LTCLobe(a).eval(wo, wi)
    # a flat footprint keeps the micro roughness (eq. 7 exact at alpha_meso = 0)
    assert MultiscaleLobe(0.2, 1.0).eval(wo, wi) == pytest.approx(LTCLobe(0.2).eval(wo, wi))


def test_leadr_lobe_is_point_light_on_the_upper_hemisphere():
    rng = np.random.default_rng(1)
    mu, cov = [0.3, -0.2], [[0.05, 0.01], [0.01, 0.03]]
    wo = view(70)
    wi = rng.normal(size=(5000, 3))
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    lobe = LeadrLobe(mu, cov, f0=0.5)
    ref = point_light(wo, wi, mu, cov, f0=0.5)
    up = wi[:, 2] > 0.0
    np.testing.assert_allclose(lobe.eval(wo, wi)[up], ref[up], rtol=1e-12, atol=1e-300)
    assert np.all(lobe.eval(wo, wi)[~up] == 0.0)
    # Fresnel 1: the non-centred Beckmann model's own BRDF
    np.testing.assert_allclose(LeadrLobe(mu, cov).eval(wo, wi), Beckmann(mu, cov).eval(wo, wi),
                               rtol=1e-12, atol=1e-300)


def test_glint_lobe_failed_draws_weigh_nothing():
    # a view grazing enough that some half vectors face away from it: those draws come back
    # below the horizon with weight 0, and the pdf integrates to the share of the others
    lobe = GlintLobe(_glint_surface(), (20.3, 33.7), 1.5)
    wo = view(89.5)
    wi, weight = draw(lobe, wo, 20_000, 4)
    failed = lobe.pdf(wo, wi) == 0.0
    assert failed.any()
    assert np.all(weight[failed] == 0.0) and np.all(wi[failed, 2] < 0.0)
