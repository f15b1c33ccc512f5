"""Warps and frames of prefilter.sphere, checked by closed forms and chi-square tests."""

import numpy as np
import pytest

from prefilter.sphere import (
    chi2_sphere,
    cosine_hemisphere,
    cosine_hemisphere_pdf,
    frame_from_normal,
    spherical_direction,
    to_local,
    to_world,
    uniform_sphere,
    uniform_sphere_pdf,
)


def test_spherical_direction_closed_form():
    w = spherical_direction([0.0, np.pi / 2, np.pi], [0.0, np.pi / 2, 0.3])
    np.testing.assert_allclose(w, [[0, 0, 1], [0, 1, 0], [0, 0, -1]], atol=1e-15)


def test_frames_orthonormal_right_handed_everywhere():
    rng = np.random.default_rng(1)
    n = uniform_sphere(rng.random((20000, 2)))
    # Include the poles and directions within 1e-12 of -z, where naive frames break down.
    n = np.concatenate([n, [[0, 0, 1], [0, 0, -1], [1e-12, 0, -1], [0, 1e-9, -1]]])
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    t, b = frame_from_normal(n)
    for u, v in [(t, t), (b, b)]:
        np.testing.assert_allclose(np.sum(u * v, -1), 1.0, atol=1e-12)
    for u, v in [(t, b), (t, n), (b, n)]:
        np.testing.assert_allclose(np.sum(u * v, -1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-12)


def test_local_world_round_trip():
    rng = np.random.default_rng(2)
    n = uniform_sphere(rng.random((100, 2)))
    w = uniform_sphere(rng.random((100, 2)))
    t, b = frame_from_normal(n)
    loc = to_local(w, t, b, n)
    np.testing.assert_allclose(loc[:, 2], np.sum(w * n, -1), atol=1e-14)
    np.testing.assert_allclose(to_world(loc, t, b, n), w, atol=1e-14)


@pytest.mark.parametrize(
    "warp, pdf, total",
    [(cosine_hemisphere, cosine_hemisphere_pdf, 1.0), (uniform_sphere, uniform_sphere_pdf, 1.0)],
)
def test_warps_match_their_pdfs(warp, pdf, total):
    w = warp(np.random.default_rng(3).random((200_000, 2)))
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-12)
    res = chi2_sphere(w, pdf)
    assert res.passed(), res
    assert res.mass_in_cap == pytest.approx(total, abs=1e-9)


def test_cosine_pdf_closed_form_moments():
    # E[z] under z/pi on the hemisphere is 2/3; E[x] = E[y] = 0.
    w = cosine_hemisphere(np.random.default_rng(4).random((400_000, 2)))
    assert np.all(w[:, 2] >= 0)
    np.testing.assert_allclose(w.mean(0), [0, 0, 2 / 3], atol=4 * 0.6 / np.sqrt(len(w)))
