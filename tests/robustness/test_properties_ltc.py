"""Property-based tests of prefilter.ltc: the LTC distribution, polygon integrals (edge-on,
zero-area, collinear, below-horizon polygons) and the anisotropic table lookup."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.ltc import (
    LTC,
    AnisoGGXTable,
    clamped_cosine_integral,
    polygon_integral,
    polygon_integral_minv,
)

N = settings.default.max_examples

# The six faces of the cube [-1, 1]^3, wound counter-clockwise seen from the centre: together
# they cover the sphere once, so any normalised distribution integrates to exactly 1 over them.
_C = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
_FACES = []
for axis in range(3):
    for s in (-1.0, 1.0):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        quad = []
        for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            p = np.zeros(3)
            p[axis], p[u], p[v] = s, a, b
            quad.append(p)
        quad = np.array(quad)
        # face normal (right-hand) must point to the centre (the shading point)
        nrm = np.cross(quad[1] - quad[0], quad[2] - quad[0])
        if nrm @ (-quad.mean(0)) < 0:
            quad = quad[::-1]
        _FACES.append(quad)
CUBE = np.array(_FACES)  # (6, 4, 3)

finite = st.floats(-3.0, 3.0)


@st.composite
def matrices(draw):
    """Invertible 3x3 matrices with condition number up to ~1e4 (LTC fits reach ~1e3)."""
    q1 = np.array([draw(finite) for _ in range(9)]).reshape(3, 3)
    q, _ = np.linalg.qr(q1 + 1e-3 * np.eye(3))
    r, _ = np.linalg.qr(np.array([draw(finite) for _ in range(9)]).reshape(3, 3) + np.eye(3))
    e = draw(st.floats(-2.0, 2.0))
    s = np.array([1.0, 10.0**e, 10.0 ** draw(st.floats(-2.0, 2.0))])
    return q @ np.diag(s) @ r


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


@settings(max_examples=N)
@given(matrices())
@example(np.eye(3))
@example(np.diag([1.0, 100.0, 0.01]))
@example(np.diag([-1.0, 1.0, 1.0]))  # mirrored lobe
def test_ltc_integrates_to_one_over_the_cube(M):
    # closed form: int_S2 D = 1 (Heitz et al. 2016 eq. 3) for any invertible M
    faces = polygon_integral(M, CUBE)
    assert np.all(np.isfinite(faces)) and np.all((faces >= 0.0) & (faces <= 1.0 + 1e-12))
    assert faces.sum() == pytest.approx(1.0, abs=1e-9)
    faces_minv = polygon_integral_minv(np.linalg.inv(M), CUBE)
    assert np.allclose(faces, faces_minv, atol=1e-12)


@settings(max_examples=N)
@given(matrices(), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
@example(np.diag([1.0, 100.0, 0.01]), 1.0, 1.0)
@example(np.eye(3), 0.5, 0.5)
def test_ltc_sample_pdf_eval_agree(M, u1, u2):
    ltc = LTC(M)
    w = ltc.sample(np.array([u1, u2]))
    assert np.isclose(np.linalg.norm(w), 1.0)
    d = ltc.eval(w)
    assert np.isfinite(d) and d >= 0.0 and ltc.pdf(w) == d
    # closed form: D(w) = Do(w') |det M^-1| / |M^-1 w|^3 with Do the clamped cosine / pi
    lw = np.linalg.solve(M, w)
    L = np.linalg.norm(lw)
    if lw[2] / L > 1e-6:  # u on the square's border maps to the horizon: rounding decides
        assert d == pytest.approx(lw[2] / L / np.pi / abs(np.linalg.det(M)) / L**3, rel=1e-8)


@st.composite
def polygons(draw):
    n = draw(st.integers(3, 6))
    centre = np.array([draw(st.floats(-2, 2)), draw(st.floats(-2, 2)), draw(st.floats(-2, 2))])
    # a convex polygon: a regular n-gon in a random plane
    normal = np.array([draw(finite), draw(finite), draw(finite)]) + np.array([0, 0, 1e-3])
    normal /= np.linalg.norm(normal)
    t = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(normal, t)
    r = 10.0 ** draw(st.floats(-3.0, 1.0))
    ang = np.arange(n) * 2 * np.pi / n
    return centre + r * (np.cos(ang)[:, None] * t + np.sin(ang)[:, None] * b)


@settings(max_examples=N)
@given(matrices(), polygons())
def test_polygon_integral_bounds_and_winding(M, P):
    one = polygon_integral(M, P)
    back = polygon_integral(M, P[::-1])
    two = polygon_integral(M, P, two_sided=True)
    assert np.isfinite(one) and 0.0 <= one <= 1.0 + 1e-12 and 0.0 <= back <= 1.0 + 1e-12
    # one face or the other is lit: one-sided(P) + one-sided(reversed P) = two-sided(P)
    assert one * back == 0.0
    assert one + back == pytest.approx(two, abs=1e-12)


@settings(max_examples=N)
@given(matrices(), finite, finite, finite, finite, finite, finite, st.integers(3, 5))
@example(np.eye(3), 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 3)  # collinear through the origin
def test_degenerate_polygons_give_zero(M, x0, y0, z0, x1, y1, z1, n):
    a, b = np.array([x0, y0, z0]), np.array([x1, y1, z1])
    t = np.linspace(0.0, 1.0, n)[:, None]
    collinear = a + t * (b - a)
    repeated = np.repeat(a[None], n, axis=0)
    # a polygon whose plane passes through the shading point (a light exactly edge-on)
    c = np.cross(a, b)
    edge_on = np.array([a, b, -a + 0.5 * b]) if np.linalg.norm(c) > 1e-3 else repeated
    for P in (collinear, repeated, edge_on):
        assert polygon_integral(M, P) == 0.0
        assert polygon_integral(M, P, two_sided=True) == 0.0
        assert clamped_cosine_integral(P) == 0.0


@settings(max_examples=N)
@given(st.floats(0.0, 3.0), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(0.01, 5.0))
@example(0.0, 0.0, 0.0, 1.0)  # a light exactly on the horizon plane
def test_clamped_cosine_horizon(depth, cx, cy, half):
    # a horizontal square at height -depth (on or below the horizon) receives nothing,
    # whichever way it faces; at height +1 with half-width 1e7 it covers the hemisphere (=1)
    sq = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    P = sq * half + np.array([cx, cy, -depth])
    assert clamped_cosine_integral(P, two_sided=True) == 0.0
    big = sq * 1e7 + np.array([0.0, 0.0, 1.0])
    assert clamped_cosine_integral(big[::-1]) == pytest.approx(1.0, abs=1e-9)


def test_form_factor_closed_form():
    # Lambert's form factor of a unit square above the point, one corner at the zenith:
    # F = 1/(2 pi) (atan(1) ... ) closed form for a rectangle a x b at distance c:
    a = b = c = 1.0
    x, y = a / c, b / c
    F = (1 / (2 * np.pi)) * (x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
                             + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y)))
    P = np.array([[0, 0, c], [0, b, c], [a, b, c], [a, 0, c]], float)
    assert clamped_cosine_integral(P) == pytest.approx(F, rel=1e-12)


# -- the anisotropic table lookup ----------------------------------------------------------------


@pytest.fixture(scope="module")
def aniso():
    return AnisoGGXTable.load()


theta_deg = st.one_of(st.sampled_from([0.0, 89.9]), st.floats(0.0, 89.9))
alpha = st.one_of(st.sampled_from([1e-3, 1.0]), st.floats(-3.0, 0.0).map(lambda e: 10.0**e))


@settings(max_examples=N)
@given(theta_deg, st.floats(0.0, 2 * np.pi), alpha, alpha)
@example(89.9, 0.0, 1e-3, 0.1)
@example(89.9, 0.0, 1.0, 0.01)
def test_aniso_lookup_gives_an_ltc(aniso, t, p, ax, ay):
    th = np.radians(t)
    wo = np.array([np.sin(th) * np.cos(p), np.sin(th) * np.sin(p), np.cos(th)])
    M, mag, fr = aniso.lookup(wo, ax, ay)
    assert np.all(np.isfinite(M)) and np.linalg.det(M) > 0.0
    assert np.isfinite(mag) and 0.0 <= mag <= 1.0 + 1e-3  # magnitude = albedo <= 1
    assert np.isfinite(fr) and 0.0 <= fr <= 1.0
    assert polygon_integral(M, CUBE).sum() == pytest.approx(1.0, abs=1e-6)


@settings(max_examples=N)
@given(theta_deg, st.floats(0.0, 2 * np.pi), alpha, alpha, polygons(), st.booleans())
@example(89.9, 0.0, 1e-3, 1.0, np.array([[-1e7, -1e7, 1.0], [1e7, -1e7, 1.0], [1e7, 1e7, 1.0],
                                          [-1e7, 1e7, 1.0]])[::-1], False)  # the sky
def test_aniso_shade_in_unit_interval(aniso, t, p, ax, ay, P, two_sided):
    th = np.radians(t)
    wo = np.array([np.sin(th) * np.cos(p), np.sin(th) * np.sin(p), np.cos(th)])
    e = aniso.shade(wo, ax, ay, P, two_sided=two_sided)
    # magnitude (albedo <= 1) times an integral of a normalised distribution (<= 1)
    assert np.isfinite(e) and 0.0 <= e <= 1.0 + 1e-3


# -- invalid input -------------------------------------------------------------------------------


@pytest.mark.parametrize("M", [np.full((3, 3), np.nan), np.zeros((3, 3)), np.eye(2),
                               np.ones((3, 3)), [[1, 0, 0], [0, 1, 0], [0, 0, np.inf]], "M"])
def test_bad_matrices_rejected(M):
    expect_error(lambda: LTC(M), "M")
    expect_error(lambda: polygon_integral(M, CUBE[0]), "M")
    expect_error(lambda: polygon_integral_minv(M, CUBE[0]), "M_inv")


@pytest.mark.parametrize("V", [np.zeros((2, 3)), np.zeros((4, 2)), np.full((4, 3), np.nan),
                               np.zeros(3), [[0, 0, 1], [1, 0, 1], [np.inf, 1, 1]]])
def test_bad_vertices_rejected(V):
    expect_error(lambda: polygon_integral(np.eye(3), V), "vertices")
    expect_error(lambda: clamped_cosine_integral(V), "vertices")


def test_bad_batch_and_flags_rejected():
    expect_error(lambda: polygon_integral(np.stack([np.eye(3)] * 2), CUBE[:3]), "vertices")
    expect_error(lambda: polygon_integral(np.eye(3), CUBE[0], two_sided="yes"), "two_sided")
    ltc = LTC(np.eye(3))
    expect_error(lambda: ltc.eval([0.0, 0.0, 2.0]), "w")
    expect_error(lambda: ltc.eval([np.nan, 0.0, 1.0]), "w")
    expect_error(lambda: ltc.sample([0.5, 1.5]), "u")


def test_aniso_lookup_rejects_bad_input(aniso):
    expect_error(lambda: aniso.lookup([0.0, 0.6, -0.8], 0.3, 0.3), "wo")
    expect_error(lambda: aniso.lookup([0.0, 0.0, 1.0], -0.3, 0.3), "alpha_x")
    expect_error(lambda: aniso.lookup([0.0, 0.0, 1.0], 0.3, np.nan), "alpha_y")
    expect_error(lambda: aniso.lookup(np.tile([0.0, 0.0, 1.0], (3, 1)), [0.1, 0.2], 0.3),
                 "alpha_x")
