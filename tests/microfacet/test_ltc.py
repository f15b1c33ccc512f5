"""The compiled GGX LTC helpers (``prefilter.microfacet.ltc``) against the table's NumPy lookup and
the LTC lobe, and the density's integral over a polygon against the polygon formula."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.ltc import LTC
from prefilter.ltc.lobe import LTCLobe
from prefilter.ltc.table import shipped_table
from prefilter.microfacet.ltc import ltc_density, ltc_lookup
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral_minv

TABLE = shipped_table()
ARRAYS = tuple(np.ascontiguousarray(getattr(TABLE, a), dtype=np.float64)
               for a in ("axis_t", "axis_r", "M", "magnitude", "fresnel"))


def _lookup(wo, alpha):
    tm, mm = np.zeros(10), np.empty(9)
    ok, mag, fres = ltc_lookup(wo[0], wo[1], wo[2], alpha, *ARRAYS, mm, tm)
    assert ok
    return tm, mag, fres


def _views(rng, n):
    w = rng.normal(size=(n, 3))
    w[:, 2] = np.abs(w[:, 2]) + 0.02
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


def test_lookup_and_density_match_the_table_and_the_lobe():
    rng = np.random.default_rng(1)
    for wo, alpha in zip(_views(rng, 40), rng.uniform(0.02, 1.0, 40)):
        tm, mag, fres = _lookup(wo, alpha)
        M, mag_np, fres_np = TABLE.lookup(wo[None], np.array([alpha]))
        assert mag == pytest.approx(float(mag_np[0]), rel=1e-12)
        assert fres == pytest.approx(float(fres_np[0]), rel=1e-12, abs=1e-15)
        wi = _views(rng, 64)
        wi[::3, 2] *= -1.0  # some below the horizon, where D_M may still be positive
        lobe = LTCLobe(alpha)
        ref = lobe.pdf(np.broadcast_to(wo, wi.shape), wi)
        got = np.array([ltc_density(tm, *w) for w in wi])
        assert np.allclose(got, ref, rtol=1e-9, atol=1e-12 * ref.max())
        # tm is M^-1 up to a factor of either sign (tm[9] undoes a mirror)
        assert np.allclose(LTC(M[0]).eval(wi), got, rtol=1e-9, atol=1e-12 * ref.max())


def test_density_integrates_to_the_polygon_formula():
    # Monte Carlo of D_M over a quad crossing the horizon (uniform on the sphere) against the
    # closed form with tm after clipping at the horizon, as the reference's control variate uses
    rng = np.random.default_rng(2)
    wo = np.array([-np.sin(0.9), 0.0, np.cos(0.9)])
    tm, _, _ = _lookup(wo, 0.4)
    quad = np.array([[0.3, -0.8, -0.3], [0.3, 0.8, -0.3], [1.5, 0.8, 1.2], [1.5, -0.8, 1.2]])
    quad = quad[::-1] if np.cross(quad[1] - quad[0], quad[2] - quad[0]) @ quad[0] > 0 else quad
    exact = float(polygon_integral_minv(tm[:9].reshape(3, 3) * tm[9], clip_to_horizon(quad)))
    n = 400_000
    w = rng.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    # inside the quad's cone (the same side of every edge's plane, towards the quad) and above
    # the horizon
    side = np.stack([w @ np.cross(quad[i], quad[(i + 1) % 4]) for i in range(4)])
    inside = ((np.all(side > 0.0, axis=0) | np.all(side < 0.0, axis=0))
              & (w @ quad.mean(axis=0) > 0.0) & (w[:, 2] > 0.0))
    d = np.array([ltc_density(tm, *x) for x in w[inside]])
    est = d.sum() * 4 * np.pi / n
    se = np.sqrt(np.sum(d * d) / n - (d.sum() / n) ** 2) * 4 * np.pi / np.sqrt(n)
    assert exact > 0.05
    assert abs(est - exact) < 5 * se, (est, exact, se)
