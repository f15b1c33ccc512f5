"""Polygon integrals of the clamped cosine and of LTCs, against closed forms and Monte Carlo.

Monte Carlo checks use 1e6 samples and a tolerance of 5 standard errors computed from the samples.
Polygons are wound counter-clockwise seen from the shading point (front faces) unless stated.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from ltc_numpy import polygon_integral_numpy

from prefilter.errors import PrefilterError
from prefilter.ltc import LTC, clamped_cosine_integral, polygon_integral, polygon_integral_minv
from prefilter.sphere.polygon import _atan2_pos
from prefilter.sphere import cosine_hemisphere

N_MC = 1_000_000


# ---------------------------------------------------------------- geometry helpers (test-only)


def rot_z(g):
    c, s = np.cos(g), np.sin(g)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def facing_origin(poly):
    """``poly`` wound so that its right-hand normal points toward the origin (front face)."""
    poly = np.asarray(poly, float)
    n = np.cross(poly[1] - poly[0], poly[2] - poly[0])
    return poly if n @ poly.mean(axis=0) < 0 else poly[::-1].copy()


def regular_polygon(k, centre, axis, radius, phase=0.0):
    """Regular k-gon, circumradius ``radius``, in the plane through ``centre`` normal to ``axis``"""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    t = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    ang = phase + 2 * np.pi * np.arange(k) / k
    ring = np.cos(ang)[:, None] * t + np.sin(ang)[:, None] * b
    return np.asarray(centre, float) + radius * ring


def random_convex_polygon(rng, k, centre, radius, axis=None):
    """Convex k-gon: sorted random angles on a circle in a plane through ``centre`` normal to
    ``axis`` (random if None)."""
    axis = rng.normal(size=3) if axis is None else np.asarray(axis, float)
    poly = regular_polygon(k, centre, axis, radius)
    ang = np.sort(rng.uniform(0, 2 * np.pi, k))
    t = (poly[0] - centre) / radius
    b = np.cross(axis / np.linalg.norm(axis), t)
    return np.asarray(centre) + radius * (np.cos(ang)[:, None] * t + np.sin(ang)[:, None] * b)


def ray_hits(poly, d):
    """Which rays from the origin along ``d (N, 3)`` hit the convex planar polygon ``poly (k, 3)``:
    ``d`` is inside the cone over the polygon iff every ``d . (v_i x v_i+1)`` has the sign that the
    polygon's centroid gives them."""
    C = np.cross(poly, np.roll(poly, -1, axis=0))
    s = np.sign(C @ poly.mean(axis=0))
    assert np.all(s == s[0]), "polygon must be convex and not contain the origin in its plane"
    C = C * s[0]
    # explicit products: a (N, 3) @ (3, k) BLAS call is slow with busy threads
    dots = d[:, :1] * C[:, 0] + d[:, 1:2] * C[:, 1] + d[:, 2:] * C[:, 2]
    return np.all(dots >= 0, axis=1)


@functools.lru_cache(maxsize=8)
def cosine_samples(seed):
    return cosine_hemisphere(np.random.default_rng(seed).random((N_MC, 2)))


def mc_clamped_cosine(poly, seed):
    """Hit fraction of cosine-distributed directions: an unbiased estimate of the form factor."""
    d = cosine_samples(seed)
    p = ray_hits(poly, d).mean()
    return p, np.sqrt(p * (1 - p) / N_MC)


def rect_form_factor(x0, x1, y0, y1, c):
    """Differential area (normal z) to the rectangle [x0,x1]x[y0,y1] at height c (standard formula,
    corner-based superposition)."""

    def F(x, y):
        X, Y = x / c, y / c
        a, b = np.sqrt(1 + X * X), np.sqrt(1 + Y * Y)
        return (X / a * np.arctan(Y / a) + Y / b * np.arctan(X / b)) / (2 * np.pi)

    return F(x1, y1) - F(x0, y1) - F(x1, y0) + F(x0, y0)


def rect(x0, x1, y0, y1, c):
    """The rectangle at height c facing down (front face toward a shading point below it)."""
    return np.array([[x0, y0, c], [x0, y1, c], [x1, y1, c], [x1, y0, c]], float)


def cube_faces(lo, hi, R=np.eye(3)):
    """The 6 faces ``(6, 4, 3)`` of the box [lo, hi], all facing inward, rotated by R."""
    c = np.array([[lo[0], lo[1], lo[2]], [hi[0], lo[1], lo[2]], [hi[0], hi[1], lo[2]],
                  [lo[0], hi[1], lo[2]], [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]],
                  [hi[0], hi[1], hi[2]], [lo[0], hi[1], hi[2]]])
    idx = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]
    faces = c[idx] @ R.T
    centre = c.mean(axis=0) @ R.T
    out = []
    for f in faces:  # inward: right-hand normal toward the box centre
        n = np.cross(f[1] - f[0], f[2] - f[0])
        out.append(f if n @ (centre - f[0]) > 0 else f[::-1])
    return np.array(out)


def random_ltc_matrix(rng, max_cond=20.0):
    while True:
        M = np.eye(3) + 0.5 * rng.normal(size=(3, 3))
        if np.linalg.cond(M) < max_cond:
            return M


# ---------------------------------------------------------------- closed forms


def test_parallel_rectangle_matches_standard_form_factor():
    rng = np.random.default_rng(0)
    x0, y0 = rng.uniform(-3, 1, (2, 50))
    x1, y1 = np.array([x0, y0]) + rng.uniform(0.01, 4, (2, 50))
    c = rng.uniform(0.05, 3, 50)
    polys = np.stack([rect(*a) for a in zip(x0, x1, y0, y1, c)])
    got = clamped_cosine_integral(polys)
    np.testing.assert_allclose(got, rect_form_factor(x0, x1, y0, y1, c), rtol=0, atol=1e-10)


@pytest.mark.parametrize("size", [1e-3, 1e-5])
def test_small_patch_is_point_source(size):
    # E ~ A cos(theta_light) cos(theta_surface) / (pi r^2), relative error O((size / r)^2);
    # at 1e-5 the edges subtend 1e-5 rad: acos(dot) would be off by ~1e-8 rad per edge, i.e.
    # ~100 % of E ~ 1e-11; atan2 keeps ~1e-6 (the cancellation of the edge sum is the limit)
    rng = np.random.default_rng(1)
    for _ in range(10):
        p = rng.normal(size=3)
        p[2] = abs(p[2]) + 0.2
        r = np.linalg.norm(p)
        normal = -p / r + 0.5 * rng.normal(size=3)  # facing the origin, tilted
        normal /= np.linalg.norm(normal)
        s = size * r
        poly = facing_origin(regular_polygon(4, p, normal, s / np.sqrt(2)))
        expected = s * s * abs(normal @ p / r) * (p[2] / r) / (np.pi * r * r)
        np.testing.assert_allclose(clamped_cosine_integral(poly), expected, rtol=1e-5)


@pytest.mark.parametrize("beta,alpha", [(0.0, 0.3), (0.6, 0.5), (1.2, 0.3), (0.2, 1.2)])
def test_polygon_sandwiches_spherical_cap(beta, alpha):
    # a cap of half-angle alpha around an axis at angle beta from z (beta + alpha <= pi/2):
    # int_cap cos / pi = cos(beta) sin^2(alpha); an inscribed and a circumscribed 128-gon bound it
    axis = np.array([np.sin(beta), 0.0, np.cos(beta)])
    k = 128
    inner = facing_origin(regular_polygon(k, axis, axis, np.tan(alpha)))
    outer = facing_origin(regular_polygon(k, axis, axis, np.tan(alpha) / np.cos(np.pi / k)))
    e_in, e_out = clamped_cosine_integral(np.stack([inner, outer]))
    cap = np.cos(beta) * np.sin(alpha) ** 2
    assert e_in < cap < e_out
    assert e_out - e_in < 1e-3 * cap


def test_huge_quad_above_covers_hemisphere():
    L = 1e8
    assert clamped_cosine_integral(rect(-L, L, -L, L, 1.0)) == pytest.approx(1.0, abs=1e-12)
    # a huge light through the shading point's horizon, tilted: clipping keeps the part above,
    # which covers the half-space on one side of the light's plane (half the hemisphere by
    # symmetry of the cosine about the yz-plane... for a vertical light through the normal axis)
    wall = facing_origin(np.array([[1.0, -L, -L], [1.0, L, -L], [1.0, L, L], [1.0, -L, L]]))
    assert clamped_cosine_integral(wall) == pytest.approx(0.5, abs=1e-7)


def test_closed_box_around_point_integrates_to_one_for_cosine():
    rng = np.random.default_rng(2)
    for _ in range(20):
        lo = -rng.uniform(0.1, 2, 3)
        hi = rng.uniform(0.1, 2, 3)
        faces = cube_faces(lo, hi, random_rotation(rng))  # faces straddle the horizon
        assert clamped_cosine_integral(faces).sum() == pytest.approx(1.0, abs=1e-12)
        assert clamped_cosine_integral(faces[:, ::-1]).sum() == 0.0  # all back faces


def test_closed_box_integrates_ltc_to_one_for_random_matrices():
    # any LTC integrates to 1 over the sphere; the inward faces of a box tile it exactly
    rng = np.random.default_rng(3)
    for i in range(20):
        M = np.eye(3) + 0.7 * rng.normal(size=(3, 3))
        if i % 2:
            M = M @ np.diag([-1.0, 1.0, 1.0])  # negative determinant: a mirrored lobe
        faces = cube_faces(-rng.uniform(0.1, 2, 3), rng.uniform(0.1, 2, 3), random_rotation(rng))
        total = polygon_integral(M, faces).sum()
        assert total == pytest.approx(1.0, abs=1e-9), (i, np.linalg.cond(M))


def test_lobe_tilted_below_the_horizon_counts_there():
    # M = R (a rotation): int_P D = E(R^T P), so for P = R Q it is Q's form factor, even where
    # P dips below the shading horizon (the LTC's support is R's hemisphere, not z >= 0)
    g = 1.2
    R = np.array([[np.cos(g), 0, np.sin(g)], [0, 1, 0], [-np.sin(g), 0, np.cos(g)]])
    Q = rect(-2, 2, -1, 0.5, 1.0)
    P = Q @ R.T
    assert P[:, 2].min() < 0 < P[:, 2].max()
    e = rect_form_factor(-2, 2, -1, 0.5, 1.0)
    assert polygon_integral(R, P) == pytest.approx(e, abs=1e-12)
    assert polygon_integral_minv(R.T, P) == pytest.approx(e, abs=1e-12)


def test_below_horizon_is_zero():
    poly = rect(-1, 1, -1, 1, -0.5)[::-1]  # faces up toward the origin, but below it
    assert clamped_cosine_integral(poly, two_sided=True) == 0.0
    M = np.array([[1, 0, 0.5], [0, 1, 0], [0, 0, 1.0]])
    assert polygon_integral(M, poly, two_sided=True) >= 0.0


# ---------------------------------------------------------------- winding, sides, symmetry


def test_winding_and_sides():
    front = rect(-1, 2, -0.5, 1, 1.5)
    back = front[::-1]
    e = rect_form_factor(-1, 2, -0.5, 1, 1.5)
    assert clamped_cosine_integral(front) == pytest.approx(e, abs=1e-12)
    assert clamped_cosine_integral(back) == 0.0
    assert clamped_cosine_integral(back, two_sided=True) == pytest.approx(e, abs=1e-12)
    assert clamped_cosine_integral(front, two_sided=True) == pytest.approx(e, abs=1e-12)
    # a cyclic shift of the vertex list is the same polygon
    assert clamped_cosine_integral(np.roll(front, 1, axis=0)) == pytest.approx(e, abs=1e-12)


def test_mirror_matrix_keeps_the_emitting_face():
    # M = diag(-1, 1, 1) mirrors the cosine, which is symmetric: the integral is unchanged and
    # the front face still emits (the sign of det M must not flip one-sidedness)
    front = rect(-0.3, 2, -1, 0.4, 0.8)
    e = rect_form_factor(-0.3, 2, -1, 0.4, 0.8)
    assert polygon_integral(np.diag([-1.0, 1, 1]), front) == pytest.approx(e, abs=1e-12)
    assert polygon_integral(np.diag([-1.0, 1, 1]), front[::-1]) == 0.0


def test_negated_matrix_is_the_point_reflected_lobe():
    # (-M)^-1 w = -(M^-1 w), so D_{-M}(w) = D_M(-w): int_P D_{-M} = int_{-P} D_M. -P has the
    # opposite facing, so the one-sided value for P must equal the two-sided value for -P
    rng = np.random.default_rng(5)
    for _ in range(10):
        M = random_ltc_matrix(rng)
        poly = facing_origin(random_convex_polygon(rng, 4, -M[:, 2] + 0.3 * rng.normal(size=3),
                                                   0.8))
        want = polygon_integral(M, -poly, two_sided=True)
        assert want > 1e-3
        assert polygon_integral(-M, poly) == pytest.approx(want, abs=1e-12)
        assert polygon_integral(-M, poly[::-1]) == 0.0


def test_rotation_about_normal_invariance():
    rng = np.random.default_rng(4)
    for _ in range(20):
        poly = facing_origin(random_convex_polygon(rng, 5, rng.normal(size=3) + [0, 0, 0.3], 1.0))
        e = clamped_cosine_integral(poly, two_sided=True)
        rotated = poly @ rot_z(rng.uniform(0, 2 * np.pi)).T
        assert clamped_cosine_integral(rotated, two_sided=True) == pytest.approx(e, abs=1e-13)


def test_matrix_scale_and_z_rotation_leave_integral_unchanged_broadcast():
    # LTC(s Rz) is the cosine itself, so every entry equals the rectangle form factor
    M = np.stack([s * rot_z(g) for s, g in [(1, 0), (2.5, 0.3), (0.1, -2.0)]])[:, None]
    x0 = np.linspace(-2, 0.5, 5)
    polys = np.stack([rect(a, a + 1.5, -0.7, 0.9, 1.2) for a in x0])
    got = polygon_integral(M, polys)
    assert got.shape == (3, 5)
    expected = rect_form_factor(x0, x0 + 1.5, -0.7, 0.9, 1.2)
    np.testing.assert_allclose(got, np.broadcast_to(expected, (3, 5)), atol=1e-12)
    got_inv = polygon_integral_minv(np.linalg.inv(M), polys)
    np.testing.assert_allclose(got_inv, np.broadcast_to(expected, (3, 5)), atol=1e-12)


# ---------------------------------------------------------------- Monte Carlo


@pytest.mark.parametrize("k", [3, 4, 5, 6, 9])
def test_convex_polygons_match_monte_carlo(k):
    rng = np.random.default_rng(10 + k)
    # one well above the horizon, one straddling it
    for centre in ([0.4, -0.3, 1.2], [0.8, 0.5, 0.1]):
        poly = facing_origin(random_convex_polygon(rng, k, np.array(centre), 0.9))
        p, se = mc_clamped_cosine(poly, seed=k)
        assert abs(clamped_cosine_integral(poly, two_sided=True) - p) < 5 * se + 1e-12
        assert abs(clamped_cosine_integral(poly) - p) < 5 * se + 1e-12


def test_straddling_quad_matches_monte_carlo():
    poly = facing_origin(np.array([[-1.0, 1, -1], [1, 1, -1], [1, 1.5, 1], [-1, 1.5, 1]]))
    p, se = mc_clamped_cosine(poly, seed=5)
    assert p > 0.01
    assert abs(clamped_cosine_integral(poly) - p) < 5 * se


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ltc_polygon_integral_matches_ltc_sampling(seed):
    # fraction of exact LTC samples w = M c / |M c| hitting P estimates int_P D
    rng = np.random.default_rng(100 + seed)
    M = random_ltc_matrix(rng)
    if seed == 2:
        M = M @ np.diag([1.0, -1.0, 1.0])
    ltc = LTC(M)
    w = ltc.sample(rng.random((N_MC, 2)))
    mean = ltc.sample(rng.random((1000, 2))).mean(axis=0)
    centre = 2.0 * mean / np.linalg.norm(mean) + 0.6 * rng.normal(size=3)
    axis = centre + 0.5 * rng.normal(size=3)
    poly = facing_origin(random_convex_polygon(rng, 4, centre, 1.5, axis))
    p = ray_hits(poly, w).mean()
    se = np.sqrt(p * (1 - p) / N_MC)
    assert p > 0.01
    assert abs(polygon_integral(M, poly, two_sided=True) - p) < 5 * se
    assert abs(polygon_integral(M, poly) - p) < 5 * se


@pytest.mark.parametrize("seed", [0, 1])
def test_ltc_polygon_integral_matches_area_sampled_eval(seed):
    # int_P D(w) dw = int_A D(x / |x|) |n . x| / |x|^3 dA, sampling x uniformly on the polygon
    rng = np.random.default_rng(200 + seed)
    M = random_ltc_matrix(rng, max_cond=8.0)
    ltc = LTC(M)
    poly = facing_origin(np.array([[-1.0, -0.5, 0.3], [1.2, -0.5, 0.2], [1.0, 0.8, 1.4],
                                   [-0.9, 0.7, 1.5]]) @ rot_z(seed * 2.0).T)
    # planar quad: split into two triangles, sample proportionally to area
    n = np.cross(poly[1] - poly[0], poly[2] - poly[0])
    poly[3] = poly[3] - (poly[3] - poly[0]) @ n / (n @ n) * n  # make it exactly planar
    tris = [poly[[0, 1, 2]], poly[[0, 2, 3]]]
    areas = np.array([np.linalg.norm(np.cross(t[1] - t[0], t[2] - t[0])) / 2 for t in tris])
    pick = rng.random(N_MC) < areas[0] / areas.sum()
    u = rng.random((N_MC, 2))
    flip = u.sum(axis=1) > 1
    u[flip] = 1 - u[flip]
    T = np.where(pick[:, None, None], tris[0], tris[1])
    x = T[:, 0] + u[:, :1] * (T[:, 1] - T[:, 0]) + u[:, 1:] * (T[:, 2] - T[:, 0])
    r = np.linalg.norm(x, axis=1)
    nu = n / np.linalg.norm(n)
    f = areas.sum() * ltc.eval(x / r[:, None]) * np.abs(x @ nu) / r**3
    est, se = f.mean(), f.std() / np.sqrt(N_MC)
    assert est > 0.01
    assert abs(polygon_integral(M, poly) - est) < 5 * se


# ---------------------------------------------------------------- degenerate input


def test_degenerate_polygons_give_zero_not_nan():
    cases = [
        np.zeros((4, 3)),  # all at the shading point
        np.tile([0.3, 0.2, 1.0], (4, 1)),  # zero area
        np.array([[0, 0, 1.0], [1, 0, 1.5], [2, 0, 2.0], [3, 0, 2.5]]),  # collinear
        np.array([[0, 0, 0.0], [1, 0, 1], [0, 1, 1]]),  # a vertex at the shading point
        np.array([[0, 0, 0.0], [1, 0, 1], [1, 1, 1], [0, 1, 0]]),  # quad with such a vertex
        np.array([[0, -1, -1.0], [0, 1, -1], [0, 1, 1], [0, -1, 1]]),  # edge-on, around the point
        rect(-1, 1, -1, 1, 0.0),  # lying in the surface plane around the point
        np.array([[1.0, 0, 1], [2, 0, 2], [1, 0, 1]]),  # repeated vertex, collinear
    ]
    M = np.array([[0.5, 0, 0.2], [0.1, 1, 0], [0.3, 0, 1.0]])
    for poly in cases:
        for two_sided in (False, True):
            assert clamped_cosine_integral(poly, two_sided=two_sided) == 0.0, poly
            assert polygon_integral(M, poly, two_sided=two_sided) == 0.0, poly


def test_near_degenerate_polygons_are_finite_and_bounded():
    rng = np.random.default_rng(6)
    eps = 10.0 ** rng.uniform(-12, -3, 200)
    sliver = np.stack([np.array([[-1.0, 0, 1], [1, 0, 1], [1, e, 1], [-1, e, 1]]) for e in eps])
    e = clamped_cosine_integral(sliver[:, ::-1])
    assert np.all(np.isfinite(e)) and np.all((e >= 0) & (e <= 1))
    np.testing.assert_allclose(e, rect_form_factor(-1, 1, 0, eps, 1.0), rtol=1e-6, atol=1e-15)
    # vertices just below / on the horizon
    poly = facing_origin(np.array([[-1.0, 1, 0.0], [1, 1, 0.0], [1, 2, 1e-300], [-1, 2, 0.0]]))
    assert np.isfinite(clamped_cosine_integral(poly))


# ---------------------------------------------------------------- shapes, determinism, errors


def test_broadcasting_shapes():
    rng = np.random.default_rng(7)
    V = rng.normal(size=(5, 4, 3)) + [0, 0, 1]
    M = np.eye(3) + 0.2 * rng.normal(size=(2, 1, 3, 3))
    assert polygon_integral(M, V).shape == (2, 5)
    assert polygon_integral(M[0, 0], V).shape == (5,)
    assert polygon_integral(M, V[0]).shape == (2, 1)
    assert polygon_integral_minv(M, V).shape == (2, 5)
    assert clamped_cosine_integral(V[0]).shape == ()
    assert clamped_cosine_integral(np.zeros((0, 4, 3))).shape == (0,)
    assert clamped_cosine_integral(rng.normal(size=(2, 3, 6, 3))).shape == (2, 3)


def test_kernel_matches_numpy_reference():
    rng = np.random.default_rng(8)
    for k in (3, 4, 5, 7):
        V = rng.normal(size=(2000, k, 3)) * [1, 1, 0.6] + [0, 0, 0.3]
        M_inv = np.eye(3) + 0.5 * rng.normal(size=(2000, 3, 3))
        for two_sided in (False, True):
            want = polygon_integral_numpy(M_inv, V, two_sided)
            np.testing.assert_allclose(polygon_integral_minv(M_inv, V, two_sided=two_sided),
                                       want, rtol=0, atol=1e-11)
    # broadcast paths (single matrix; index arrays)
    V = rng.normal(size=(3, 1, 4, 3)) + [0, 0, 0.5]
    M_inv = np.eye(3) + 0.3 * rng.normal(size=(6, 3, 3))
    np.testing.assert_allclose(polygon_integral_minv(M_inv, V), polygon_integral_numpy(M_inv, V),
                               atol=1e-11)


def test_deterministic_bytes():
    rng = np.random.default_rng(9)
    V = rng.normal(size=(10000, 4, 3))
    M = np.eye(3) + 0.3 * rng.normal(size=(10000, 3, 3))
    assert polygon_integral(M, V).tobytes() == polygon_integral(M.copy(), V.copy()).tobytes()


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: clamped_cosine_integral(np.ones((4, 2))), r"vertices.*\(\.\.\., 3\)"),
        (lambda: clamped_cosine_integral(np.ones((2, 3))), "at least 3 vertices"),
        (lambda: clamped_cosine_integral([[0, 0, 1], [1, 0, np.nan], [0, 1, 1]]), "finite"),
        (lambda: polygon_integral(np.ones((3, 2)), np.ones((3, 3))), r"M.*\(\.\.\., 3, 3\)"),
        (lambda: polygon_integral(np.ones((3, 3)), np.eye(3)), "invertible"),
        (lambda: polygon_integral_minv(np.diag([1.0, 1.0, 0.0]), np.eye(3)), "M_inv.*invertible"),
        (lambda: polygon_integral(np.tile(np.eye(3), (2, 1, 1)), np.ones((3, 4, 3))),
         "do not broadcast"),
        (lambda: polygon_integral(np.eye(3), np.eye(3), two_sided="yes"), "two_sided"),
        (lambda: polygon_integral(np.full((3, 3), np.inf), np.eye(3)), "finite"),
    ],
)
def test_validation_errors(call, match):
    with pytest.raises(PrefilterError, match=match):
        call()


def test_singular_matrix_in_a_batch_is_reported():
    M = np.tile(np.eye(3), (4, 1, 1))
    M[2, :, 1] = M[2, :, 0]
    with pytest.raises(PrefilterError, match=r"batch index \(2,\)"):
        polygon_integral(M, rect(-1, 1, -1, 1, 1.0))


def test_fast_atan2_matches_numpy():
    rng = np.random.default_rng(11)
    s = np.concatenate([np.abs(rng.normal(size=20000)), 10.0 ** rng.uniform(-200, 200, 2000),
                        [1.0, 1.0, 1e-300, 0.0]])
    d = np.concatenate([rng.normal(size=20000), rng.normal(size=2000) * 10.0 ** rng.uniform(
        -200, 200, 2000), [1.0, -1.0, -1.0, 1.0]])
    got = np.array([_atan2_pos(a, b) for a, b in zip(s, d)])
    want = np.arctan2(s, d)
    np.testing.assert_allclose(got, want, rtol=2e-15, atol=0)


@pytest.mark.slow
def test_random_sweep_against_ltc_sampling():
    # 40 random (M, polygon) pairs, k = 3..8 vertices, many straddling either horizon
    rng = np.random.default_rng(300)
    for i in range(40):
        M = random_ltc_matrix(rng, max_cond=50.0)
        ltc = LTC(M)
        w = ltc.sample(rng.random((N_MC, 2)))
        centre = w[:50].mean(axis=0) * 1.5 + 0.8 * rng.normal(size=3)
        axis = centre + 0.7 * rng.normal(size=3)
        poly = facing_origin(random_convex_polygon(rng, 3 + i % 6, centre, 1.0, axis))
        p = ray_hits(poly, w).mean()
        se = np.sqrt(max(p * (1 - p), 1e-12) / N_MC)
        assert abs(polygon_integral(M, poly, two_sided=True) - p) < 5 * se + 1e-9, i
