"""The vectorised quad-light references of the acceptance (``quadfit.quad_references``)."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.ltc.aniso.quadfit import acceptance_quads, quad_references
from prefilter.ltc.validate import reference_quad_integral
from prefilter.microfacet import GGX


def view(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@pytest.mark.parametrize("theta,phi,ax,ay", [(70, 130, 0.12, 0.5), (25, -40, 0.6, 0.08)])
def test_quad_references_match_the_scalar_estimator(theta, phi, ax, ay):
    """Same integral as ``reference_quad_integral`` (another implementation): the mean over
    independent seeds agrees within 4.5 combined standard errors, straddling quads included."""
    wo = view(theta, phi)
    quads = acceptance_quads(10, np.random.default_rng(7))
    runs = np.array([quad_references(wo, ax, ay, quads, 2048, 512, s) for s in range(16)])
    mean, se = runs.mean(0), runs.std(0, ddof=1) / 4.0
    rng = np.random.default_rng(8)
    ref = np.array([reference_quad_integral(GGX(ax, ay), wo, q, 100_000, rng) for q in quads])
    z = (mean - ref[:, 0]) / np.hypot(se, ref[:, 1])
    assert np.all(np.abs(z) < 4.5), z


def test_quad_references_hemisphere_sized_quad_gives_the_albedo():
    """A quad at height 1e-3 with half-size 1e4 sees the whole upper hemisphere except the last
    0.006 deg above the horizon: the integral is the albedo ``GGX.albedo`` (closed form
    quadrature of the model), within Monte Carlo error."""
    wo = view(40, 20)
    h, s = 1e-3, 1e4
    quad = np.array([[[-s, -s, h], [s, -s, h], [s, s, h], [-s, s, h]]])[:, ::-1]  # faces down
    g = GGX(0.3, 0.15)
    vals = np.array([quad_references(wo, 0.3, 0.15, quad, 4096, 256, k)[0] for k in range(8)])
    assert abs(vals.mean() - float(g.albedo(wo))) < 4 * vals.std(ddof=1) / np.sqrt(8) + 1e-4


def test_quad_references_reject_bad_input():
    with pytest.raises(PrefilterError, match="n_lobe"):
        quad_references(view(10, 0), 0.3, 0.3, acceptance_quads(2, 0), 0, 10, 0)
    with pytest.raises(PrefilterError, match="wo"):
        quad_references([0, 0, -1.0], 0.3, 0.3, acceptance_quads(2, 0), 10, 10, 0)
