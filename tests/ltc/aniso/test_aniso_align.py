"""Alignment of LTC matrices (anisotropic-LTC paper, eqs. 11-12)."""

import numpy as np
import pytest

from prefilter.ltc import LTC
from prefilter.ltc.aniso.align import FLIP_Y, align, alignment_cost, cosine_points, rotation_z
from prefilter.sphere import uniform_sphere


def random_ltc_matrices(n, rng):
    """Random well-conditioned LTC-like matrices: scales and skews around a lobe axis."""
    A = np.zeros((n, 3, 3))
    A[:, 0, 0] = rng.uniform(0.05, 1.0, n)
    A[:, 1, 1] = rng.uniform(0.05, 1.0, n)
    A[:, 0, 1] = rng.uniform(-0.3, 0.3, n)
    A[:, :2, 2] = rng.uniform(-0.5, 0.5, (n, 2))
    A[:, 2, 2] = 1.0
    theta = rng.uniform(0, 1.2, n)
    # tilt the lobe: rotate about x
    R = np.zeros((n, 3, 3))
    R[:, 0, 0] = 1
    R[:, 1, 1] = R[:, 2, 2] = np.cos(theta)
    R[:, 1, 2] = -np.sin(theta)
    R[:, 2, 1] = np.sin(theta)
    return R @ A


def test_equivalent_matrices_give_the_same_ltc():
    """Eq. 11: M, M Rz(gamma) and M F evaluate to the same density (closed form)."""
    rng = np.random.default_rng(0)
    M = random_ltc_matrices(20, rng)
    w = uniform_sphere(rng.random((20, 500, 2)))
    F = np.diag([-1.0, 1.0, 1.0])
    base = LTC(M[:, None]).eval(w)
    for Mp in (M @ rotation_z(rng.uniform(0, 2 * np.pi, 20)), M @ F, M @ FLIP_Y @ F):
        np.testing.assert_allclose(LTC(Mp[:, None]).eval(w), base, rtol=1e-9, atol=1e-12)


def test_align_picks_one_representative():
    """Aligning any equivalent matrix M Rz(g) F gives the same aligned matrix."""
    rng = np.random.default_rng(1)
    M = random_ltc_matrices(30, rng)
    ref = align(M)["M"]
    for F in (np.eye(3), FLIP_Y, np.diag([-1.0, 1, 1]), np.diag([-1.0, -1, 1])):
        Mp = M @ F @ rotation_z(rng.uniform(0, 2 * np.pi, 30))
        np.testing.assert_allclose(align(Mp)["M"], ref, atol=2e-4)


def test_align_minimises_eq12_by_brute_force():
    rng = np.random.default_rng(2)
    M = random_ltc_matrices(6, rng)
    res = align(M)
    c = cosine_points(24)
    g = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    for i in range(6):
        Mi = M[i] @ (FLIP_Y if res["flipped"][i] else np.eye(3))
        brute = alignment_cost(Mi @ rotation_z(g), c).min()
        assert alignment_cost(res["M"][i], c) <= brute + 1e-9
        # the mirrored class has det < 0: never chosen, even when its cost is lower
    assert np.all(np.linalg.det(res["M"]) > 0)


def test_align_fixed_points():
    D = np.diag([0.3, 0.1, 1.0])
    np.testing.assert_allclose(align(D)["M"], D, atol=1e-9)
    np.testing.assert_allclose(align(D @ rotation_z(0.7))["M"], D, atol=1e-5)
    np.testing.assert_allclose(align(np.eye(3))["M"], np.eye(3), atol=1e-9)


def test_align_rejects_singular():
    from prefilter.errors import PrefilterError

    with pytest.raises(PrefilterError, match="M"):
        align(np.diag([1.0, 0.0, 1.0]))
