"""Direct P-NDF against closed forms, quadrature and brute-force binning."""

import numpy as np
import pytest
from maps import bilinear_s, gaussian_heightfield, normals_from_s, sinusoid, sinusoid_s

from prefilter.errors import PrefilterError
from prefilter.glints import elements, hemisphere_ndf, pndf_image
from prefilter.glints.pndf import SIGMA_H, pndf


def flat(size=32):
    n = np.zeros((size, size, 3))
    n[..., 2] = 1.0
    return n


def test_flat_map_gives_the_intrinsic_gaussian():
    sr = 0.01
    s = np.array([[0.0, 0.0], [0.01, -0.004], [0.02, 0.03]])
    got = pndf(flat(), [5.5, 7.25], 3.0, s, sr)
    want = np.exp(-0.5 * (s**2).sum(-1) / sr**2) / (2 * np.pi * sr**2)
    np.testing.assert_allclose(got, want, rtol=1e-10)
    # pixel averages: separable erf masses of the same Gaussian
    from scipy.special import ndtr

    R, S = 16, 0.04
    e = np.linspace(-S, S, R + 1)
    m = np.diff(ndtr(e / sr))
    want_img = np.outer(m, m) / (2 * S / R) ** 2
    img = pndf_image(flat(), [5.5, 7.25], 3.0, R, S, sr)
    np.testing.assert_allclose(img, want_img, atol=1e-6 * want_img.max())


def test_tilted_plane_shifts_the_gaussian():
    n = normals_from_s(np.full((16, 16), 0.3), np.full((16, 16), -0.1))
    got = pndf(n, [3.0, 3.0], 2.0, [[0.3, -0.1], [0.31, -0.1]], 0.01)
    np.testing.assert_allclose(got, [1 / (2 * np.pi * 1e-4), np.exp(-0.5) / (2 * np.pi * 1e-4)],
                               rtol=1e-10)


@pytest.mark.parametrize("center,sigma_p", [([10.3, 20.7], 2.0), ([60.0, 3.0], 4.0)])
def test_hemisphere_normalisation(center, sigma_p):
    """integral D(m) m_z dm = 1 by Gauss-Legendre quadrature in (theta, phi)."""
    nm = sinusoid(64)
    tmax = np.arcsin(0.45)
    x, w = np.polynomial.legendre.leggauss(240)
    theta = 0.5 * tmax * (x + 1)
    wt = 0.5 * tmax * w
    phi = (np.arange(480) + 0.5) * 2 * np.pi / 480
    T, P = np.meshgrid(theta, phi, indexing="ij")
    m = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    D = hemisphere_ndf(pndf(nm, center, sigma_p, m[..., :2], 0.02), m)
    integral = np.sum(D * np.cos(T) * np.sin(T) * wt[:, None]) * 2 * np.pi / 480
    assert abs(integral - 1.0) < 2e-3


def test_image_is_the_pixel_average_of_the_point_density():
    """pndf_image (erf masses + line quadrature) vs 10 x 10 midpoint quadrature of pndf."""
    nm = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)  # steep: long line elements
    R, S, sr = 24, 0.3, 0.005
    h = 2 * S / R
    img = pndf_image(nm, [17.0, 9.5], 3.0, R, S, sr)
    sub = (np.arange(10) + 0.5) / 10 * h
    g = (np.linspace(-S, S, R + 1)[:-1, None] + sub).ravel()
    X, Y = np.meshgrid(g, g)
    D = pndf(nm, [17.0, 9.5], 3.0, np.stack([X, Y], -1), sr)
    ref = D.reshape(R, 10, R, 10).mean(axis=(1, 3))
    assert np.abs(img - ref).sum() / ref.sum() < 5e-3
    assert img.sum() * h * h == pytest.approx(ref.sum() * h * h, rel=2e-3)


def _chi2(img, hist, n, h, min_expected=20):
    exp = img * h * h * n
    m = exp > min_expected
    return np.mean((hist[m] - exp[m]) ** 2 / exp[m]), m.sum()


def test_closed_form_matches_monte_carlo_of_the_element_model():
    """Sample the 4D element mixture itself: footprint position, element by g_i(u), linearised
    normal + sigma_r noise, weighted by the partition sum; histogram == pndf_image."""
    nm = sinusoid(64)
    s_el, J = elements(nm)
    sr, R, S = 0.02, 32, 0.3
    h = 2 * S / R
    c, sp = np.array([10.3, 20.7]), 4.0
    rng = np.random.default_rng(1)
    n = 400_000
    u = c + sp * rng.standard_normal((n, 2))
    off = np.arange(-2, 3)
    OX, OY = (a.ravel() for a in np.meshgrid(off, off))
    base = np.floor(u).astype(int)
    cx, cy = base[:, 0, None] + OX, base[:, 1, None] + OY  # texel indices, centres at +0.5
    g = np.exp(-((u[:, 0, None] - cx - 0.5) ** 2 + (u[:, 1, None] - cy - 0.5) ** 2)
               / (2 * SIGMA_H**2))
    cdf = np.cumsum(g, 1)
    k = (cdf < rng.random(n)[:, None] * cdf[:, -1:]).sum(1)
    xi, yi = cx[np.arange(n), k] % 64, cy[np.arange(n), k] % 64
    d = np.stack([u[:, 0] - cx[np.arange(n), k] - 0.5, u[:, 1] - cy[np.arange(n), k] - 0.5], -1)
    s = s_el[yi, xi] + np.einsum("nij,nj->ni", J[yi, xi], d) + sr * rng.standard_normal((n, 2))
    e = np.linspace(-S, S, R + 1)
    wt = cdf[:, -1] / cdf[:, -1].mean()
    hist, _, _ = np.histogram2d(s[:, 1], s[:, 0], bins=[e, e], weights=wt)
    img = pndf_image(nm, c, sp, R, S, sr)
    stat, dof = _chi2(img, hist, n, h)
    assert dof > 150
    assert stat < 1.3  # chi-square per bin ~ 1 (weights add a little variance)


def test_brute_force_binning_of_the_interpolated_normals():
    """Millions of footprint positions with their (analytic / bilinear) normal + sigma_r noise.

    The element model is Yan et al.'s approximation of the normal field (Gaussian partition of
    unity, local linearisation), so on a smooth map it agrees within a small model error.
    """
    kw = dict(ax=0.2, ay=0.1, px=64, py=32)
    nm = sinusoid(128, **kw)
    sr, R, S = 0.02, 24, 0.3
    h = 2 * S / R
    c, sp = np.array([30.0, 70.0]), 6.0
    img = pndf_image(nm, c, sp, R, S, sr)
    rng = np.random.default_rng(2)
    n = 2_000_000
    u = c + sp * rng.standard_normal((n, 2))
    e = np.linspace(-S, S, R + 1)
    for field in (sinusoid_s(u, **kw), bilinear_s(nm, u)):
        s = field + sr * rng.standard_normal((n, 2))
        hist, _, _ = np.histogram2d(s[:, 1], s[:, 0], bins=[e, e])
        l1 = np.abs(hist / n - img * h * h).sum()
        assert l1 < 0.02, l1  # MC noise alone ~ 0.005 here


@pytest.mark.slow
def test_large_footprint_converges_to_beckmann():
    """Whole-map footprint over a Gaussian heightfield == Beckmann with its slope covariance."""
    nm, cov = gaussian_heightfield(256, corr=3.0, slope_std=0.15, seed=3)
    R, S, sr = 32, 0.5, 0.005
    h = 2 * S / R
    img = pndf_image(nm, [128.0, 128.0], 128.0, R, S, sr)
    sub = (np.arange(6) + 0.5) / 6 * h
    g = (np.linspace(-S, S, R + 1)[:-1, None] + sub).ravel()
    X, Y = np.meshgrid(g, g)
    mz = np.sqrt(1 - X**2 - Y**2)
    slope = np.stack([-X / mz, -Y / mz], -1)
    P = np.linalg.inv(cov)
    p22 = np.exp(-0.5 * np.einsum("...i,ij,...j->...", slope, P, slope)) / (
        2 * np.pi * np.sqrt(np.linalg.det(cov)))
    beck = (p22 / mz**4).reshape(R, 6, R, 6).mean(axis=(1, 3))
    assert np.abs(img - beck).sum() / beck.sum() < 0.08


def test_beckmann_moments_small():
    """Fast version: mean and covariance of D_p over a whole small map == the map's statistics."""
    nm, _ = gaussian_heightfield(64, corr=3.0, slope_std=0.1, seed=4)
    R, S, sr = 64, 0.5, 0.005
    h = 2 * S / R
    img = pndf_image(nm, [32.0, 32.0], 64.0, R, S, sr)
    x = np.linspace(-S, S, R + 1)[:-1] + h / 2
    X, Y = np.meshgrid(x, x)
    p = img * h * h
    s = nm[..., :2].reshape(-1, 2)
    mean = np.array([(p * X).sum(), (p * Y).sum()])
    np.testing.assert_allclose(p.sum(), 1.0, atol=1e-3)
    np.testing.assert_allclose(mean, s.mean(0), atol=2e-3)
    var = np.array([(p * X**2).sum(), (p * Y**2).sum()]) - mean**2
    # + sigma_r^2, the element spread sigma^2 |J|^2 and the pixel width h^2 / 12
    np.testing.assert_allclose(var, s.var(0) + sr**2 + h * h / 12, rtol=0.08)


def test_invalid_inputs_raise_prefilter_error():
    with pytest.raises(PrefilterError, match="normal_map"):
        pndf(np.ones((8, 8, 3)), [1, 1], 1.0, [0, 0])
    with pytest.raises(PrefilterError, match="normal_map"):
        pndf(np.zeros((8, 3)), [1, 1], 1.0, [0, 0])
    with pytest.raises(PrefilterError, match="sigma_p"):
        pndf(flat(8), [1, 1], -1.0, [0, 0])
    with pytest.raises(PrefilterError, match="intrinsic_roughness"):
        pndf(flat(8), [1, 1], 1.0, [0, 0], 0.0)
    with pytest.raises(PrefilterError, match="s"):
        pndf(flat(8), [1, 1], 1.0, [0, 0, 1])
    with pytest.raises(PrefilterError, match="support"):
        pndf_image(flat(8), [1, 1], 1.0, 8, 2.0)


def test_ndf_truncation_keeps_the_element_tails():
    """Pixels 4.6-5.9 element stds from the (flat map's) element: cut at 4 stds they are zero, at
    6 they hold the exact pixel masses (the cut the renderer's direct evaluation uses)."""
    from scipy.special import ndtr

    sr, R, S = 0.01, 24, 0.12
    h = 2 * S / R
    e = np.linspace(-S, S, R + 1)
    m = np.diff(ndtr(e / sr))
    ref = np.outer(m, m) / h**2
    ctr = e[:-1] + 0.5 * h
    X, Y = np.meshgrid(ctr, ctr)
    band = (np.hypot(X, Y) / sr > 4.6) & (np.hypot(X, Y) / sr < 5.9)
    cut4 = pndf_image(flat(), [5.5, 7.25], 3.0, R, S, sr)
    cut6 = pndf_image(flat(), [5.5, 7.25], 3.0, R, S, sr, ndf_truncation=6.0)
    # splats cover whole pixels: the first pixel past the cut may still hold mass
    far_x = np.abs(X) - 0.5 * h > 4.0 * sr + h
    assert far_x[band].sum() >= 4 and np.all(cut4[band & far_x] == 0.0)
    np.testing.assert_allclose(cut6[band], ref[band], rtol=1e-2)  # normal_cdf in the far tail
    with pytest.raises(PrefilterError, match="ndf_truncation"):
        pndf_image(flat(), [5.5, 7.25], 3.0, R, S, sr, ndf_truncation=2.0)


@pytest.mark.parametrize("name", ["pndf", "bake"])
def test_package_attribute_is_the_submodule(name):
    """``prefilter.glints.pndf`` / ``.bake`` are the modules, not their namesake functions: a
    shadowing function made ``import prefilter.glints.pndf as P; P.TRUNCATION = 6`` a no-op."""
    import importlib

    import prefilter.glints as G

    module = importlib.import_module(f"prefilter.glints.{name}")
    assert getattr(G, name) is module
    assert name not in G.__all__
    assert callable(getattr(module, name))
    exec(f"import prefilter.glints.{name} as alias", ns := {})
    assert ns["alias"] is module


def test_element_split_reassembles_the_covariance():
    """``siso^2 I + kappa^2 v v^T == sr^2 I + [[a, b], [b, d]]`` with ``|v| = 1`` (random and
    degenerate covariances: isotropic, rank one, diagonal with a < d)."""
    from prefilter.glints.pndf import element_split, principal_axis

    rng = np.random.default_rng(5)
    M = rng.normal(size=(200, 2, 2)) * rng.uniform(1e-4, 1.0, (200, 1, 1))
    covs = list(M @ M.transpose(0, 2, 1)) + [np.diag([0.3, 0.3]), np.diag([0.2, 0.5]),
                                            np.outer([0.6, 0.8], [0.6, 0.8]), np.zeros((2, 2))]
    sr = 0.01
    for C in covs:
        nu1, siso, kappa = element_split(C[0, 0], C[0, 1], C[1, 1], sr)
        vx, vy = principal_axis(C[0, 0], C[0, 1], C[1, 1], nu1)
        v = np.array([vx, vy])
        got = siso**2 * np.eye(2) + kappa**2 * np.outer(v, v)
        np.testing.assert_allclose(got, sr**2 * np.eye(2) + C, rtol=0, atol=1e-12)
        assert abs(np.linalg.norm(v) - 1.0) < 1e-14
        assert nu1 == pytest.approx(np.linalg.eigvalsh(C)[-1], abs=1e-14)


def test_line_nodes_spacing_and_normaliser():
    """Line quadrature of the rank-one part: nodes at most 1.5 siso apart, at least 9, and the
    normaliser is the sum of the node weights."""
    from prefilter.glints.pndf import line_nodes

    for kappa, siso, trunc in [(0.01, 0.005, 4.0), (0.2, 0.005, 6.0), (0.004, 0.005, 4.0)]:
        n, norm = line_nodes(kappa, siso, trunc)
        t = kappa * np.linspace(-trunc, trunc, n)
        assert n >= 9 and np.diff(t).max() <= 1.5 * siso * (1 + 1e-12)
        assert norm == pytest.approx(np.exp(-0.5 * (t / kappa) ** 2).sum(), rel=1e-12)


def _element_mixture_error(kappa, siso, trunc, n_nodes):
    """Largest error over the peak of an element's node mixture against its exact Gaussian
    ``N(0, siso^2 I + kappa^2 e_x e_x^T)`` on a grid (point values, no pixel boxes), the nodes
    from the library's one rule (``element_nodes`` / ``element_node``, which the splats, the
    Wang tiles' pixel values and rectangle masses share); ``n_nodes``: the rule expected
    (3, 5, or 0 for the line nodes)."""
    from prefilter.glints.pndf import element_node, element_nodes

    g = np.linspace(-8.0, 8.0, 641) * np.sqrt(siso**2 + kappa**2)
    X, Y = np.meshgrid(g, g)

    def iso(cx):
        return np.exp(-0.5 * ((X - cx) ** 2 + Y**2) / siso**2) / (2 * np.pi * siso**2)

    vx = siso**2 + kappa**2
    exact = np.exp(-0.5 * (X**2 / vx + Y**2 / siso**2)) / (2 * np.pi * np.sqrt(vx) * siso)
    n, norm = element_nodes(kappa, siso, trunc)
    assert n == n_nodes if n_nodes else n >= 9
    mix = 0.0
    for q in range(n):
        t, num, den, _ = element_node(kappa, trunc, n, norm, q)
        mix = mix + num / den * iso(t)
    return np.abs(mix - exact).max() / exact.max()


def test_gauss_hermite_5_nodes():
    """GH5_T, GH5_W: the 5-point Gauss-Hermite rule of the standard normal."""
    from prefilter.glints.pndf import GH5_T, GH5_W

    x, w = np.polynomial.hermite_e.hermegauss(5)
    assert np.allclose(np.sort(x)[3:], GH5_T, rtol=1e-12)
    assert np.allclose(w[2:] / w.sum(), GH5_W, rtol=1e-12)


@pytest.mark.parametrize("trunc", [5.0, 6.0])
def test_element_quadrature_within_4e_4_of_the_peak(trunc):
    """Every branch of the element rule at its worst: Gauss-Hermite at its largest kappa, the
    line rule just above it, near the isotropic std and for long elements."""
    from prefilter.glints.pndf import GH3_MAX, GH5_MAX

    siso = 0.005
    errs = {"gh3": _element_mixture_error(GH3_MAX * siso, siso, trunc, 3),
            "gh5": _element_mixture_error(GH5_MAX * siso, siso, trunc, 5)}
    for r in (GH5_MAX * 1.001, 0.8, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0):
        errs[r] = _element_mixture_error(r * siso, siso, trunc, 0)
    assert max(errs.values()) < 4e-4, errs


def test_float32_images_and_the_cut_ellipse_keep_the_mass():
    """Long line elements (steep sinusoid) inside the support: at ndf_truncation 6 the images
    hold the whole mass (the line nodes' splats cut at node_reach drop < exp(-18) each), and the
    float32 sums the bakes use agree with float64 to ~1e-5 of the peak."""
    nm = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)
    R, S, sr = 96, 1.0, 0.01
    h = 2 * S / R
    c = [[17.0, 9.5], [40.25, 33.0]]
    img64 = pndf_image(nm, c, 3.0, R, S, sr, ndf_truncation=6.0, footprint_truncation=6.0)
    img32 = pndf_image(nm, c, 3.0, R, S, sr, ndf_truncation=6.0, footprint_truncation=6.0,
                       dtype=np.float32)
    assert img32.dtype == np.float32 and img64.dtype == np.float64
    np.testing.assert_allclose(img64.sum(axis=(1, 2)) * h * h, 1.0, atol=1e-7)
    assert np.abs(img32 - img64).max() < 1e-5 * img64.max()
    with pytest.raises(PrefilterError, match="dtype"):
        pndf_image(nm, c, 3.0, R, S, sr, dtype=np.int32)
