"""SG environment lighting of glints (paper sec. 5.4): the SG sampler by chi-square, the compact
epsilon-support in closed form, the unprefiltered estimator against quadrature on a flat map,
and prefiltering's noise reduction and bias against a converged estimate."""

import math

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints import load
from prefilter.glints.bake import bake
from prefilter.glints.surface import surface
from prefilter.glints.envlight import as_lobes, eps_support, sample_sg, sg_eval, sg_pdf, shade_sg
from prefilter.sphere import chi2_sphere

MU = np.array([[5.0, 5, 5], [2, 1, 0.5]])
LAM = np.array([200.0, 30])
P = np.array([[-0.3, 0.1, 1], [0.5, 0.5, 0.7]])
P = P / np.linalg.norm(P, axis=-1, keepdims=True)
WO = np.array([math.sin(0.4), 0, math.cos(0.4)])


def test_eps_support_closed_form():
    lam = np.array([5.0, 50, 500])
    th = eps_support(np.ones((3, 3)), lam, 0.1)
    np.testing.assert_allclose(np.exp(lam * (np.cos(th) - 1)), 0.1, rtol=1e-12)
    assert eps_support(1.0, 1.0, 1e-3) == pytest.approx(math.pi)  # never drops that low


def test_as_lobes_normalises_axes_and_rejects_bad_lobes():
    mu, lam, p = as_lobes([[1, 1, 1], [0, 0, 0]], [2.0, 3.0], [[0, 0, 2], [3, 4, 0]])
    np.testing.assert_allclose(p, [[0, 0, 1], [0.6, 0.8, 0]], rtol=1e-15)
    assert mu.dtype == lam.dtype == np.float64 and lam.shape == (2,)
    per_sample = as_lobes(np.ones((2, 3)), [1.0, 1.0], np.ones((5, 2, 3)))[2]
    np.testing.assert_allclose(np.linalg.norm(per_sample, axis=-1), 1.0, rtol=1e-15)
    with pytest.raises(PrefilterError, match="mu, lam"):
        as_lobes([[1, 1, 1]], [0.0], [[0, 0, 1]])
    with pytest.raises(PrefilterError, match="lam: expected K lobes"):
        as_lobes(np.ones((2, 3)), [1.0], np.ones((2, 3)))


def test_sample_sg_chi2():
    w, pdf = sample_sg(MU, LAM, P, np.random.default_rng(0).random((200_000, 3)))
    np.testing.assert_allclose(pdf, sg_pdf(w, MU, LAM, P), rtol=1e-12)
    res = chi2_sphere(w, lambda x: sg_pdf(x, MU, LAM, P), res=(24, 48))
    assert res.passed(1e-3), res


def test_unprefiltered_estimator_matches_quadrature():
    """Flat map, intrinsic roughness 0.1: the footprint NDF is N(s; 0, 0.1^2) in closed form."""
    sr = 0.1
    nm = np.zeros((8, 8, 3))
    nm[..., 2] = 1.0
    surf = surface(None, nm, intrinsic_roughness=sr)
    lam = np.array([20.0])
    mu = np.array([[1.0, 1.0, 1.0]])
    p = np.array([[-0.35, 0.1, 0.93]])
    est = shade_sg(surf, np.full((20_000, 2), 3.0), 1.0, WO, mu, lam, p, n_samples=8,
                   prefilter=False, rng=1)[:, 0]
    # midpoint quadrature over the upper hemisphere of wi
    n = 600
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, Ph = np.meshgrid(th, ph, indexing="ij")
    wi = np.stack([np.sin(T) * np.cos(Ph), np.sin(T) * np.sin(Ph), np.cos(T)], -1)
    dw = np.sin(T) * (np.pi / 2 / n) * (np.pi / n)
    h = wi + WO
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    D = np.exp(-0.5 * np.sum(h[..., :2] ** 2, -1) / sr**2) / (2 * np.pi * sr**2)
    G = np.minimum(1, np.minimum(2 * h[..., 2] * WO[2] / (h @ WO),
                                 2 * h[..., 2] * wi[..., 2] / np.sum(wi * h, -1)))
    L = sg_eval(wi, mu, lam, p)[..., 0]
    ref = np.sum(D * G / (4 * WO[2]) * L * dw)
    assert est.mean() == pytest.approx(ref, rel=3 * est.std() / math.sqrt(est.size) / ref + 2e-3)


@pytest.fixture(scope="module")
def surf(tmp_path_factory):
    nm = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)
    out = tmp_path_factory.mktemp("ge") / "map.npz"
    bake(nm, out, rank=16, ndf_res=64, block=16, support=0.5, cell=32, converge=0.0,
         intrinsic_roughness=0.01, progress=False)
    return surface(load(out), nm)


def test_prefiltering_reduces_noise(surf):
    """500 footprints x 8 repeats of a 4-sample estimate vs a 256-sample unprefiltered one:
    prefiltering (eps 0.5) lowers the noise (measured 0.67 -> 0.59 of the mean) at a bias of
    ~8 % of the mean (the NDF blur; docs/glints-part2.md)."""
    c = np.repeat(np.random.default_rng(5).uniform(0, 64, (500, 2)), 8, 0)
    ref = shade_sg(surf, c, 6.0, WO, MU, LAM, P, n_samples=256, rng=2,
                   prefilter=False)[:, 0].reshape(500, 8).mean(1)
    out = {}
    for pre in (False, True):
        L = shade_sg(surf, c, 6.0, WO, MU, LAM, P, n_samples=4, rng=3, prefilter=pre,
                     eps=0.5)[:, 0].reshape(500, 8)
        out[pre] = (np.sqrt(np.mean(L.var(1))) / ref.mean(), L.mean() / ref.mean())
    assert out[True][0] < 0.92 * out[False][0], out
    assert abs(out[False][1] - 1) < 0.03, out
    assert abs(out[True][1] - 1) < 0.12, out


def test_sg_light_samples_are_shade_sg_samples():
    """envlight.sg_light_samples == sample_sg + sg_eval / (n pdf) per sample (its lobes are
    validated once instead of twice per sample); invalid lobes raise the same error."""
    from prefilter.glints.envlight import sg_light_samples

    rng = np.random.default_rng(5)
    mu = rng.random((3, 3))
    lam = np.array([2.0, 30.0, 300.0])
    p = rng.normal(size=(3, 3))
    u = rng.random((50, 12))
    wi, wgt = sg_light_samples(mu, lam, p, u)
    assert wi.shape == wgt.shape == (4, 50, 3)
    for j in range(4):
        w, pdf = sample_sg(mu, lam, p, u[:, 3 * j:3 * j + 3])
        np.testing.assert_allclose(wi[j], w, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(wgt[j], sg_eval(w, mu, lam, p) / (4 * pdf)[:, None],
                                   rtol=1e-12)
    with pytest.raises(PrefilterError, match="sharpness > 0"):
        sg_light_samples(mu, -lam, p, u)
