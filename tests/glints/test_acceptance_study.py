"""The per-cell measurements of ``benchmarks/study_glints_reference.py`` (issue #9 acceptance):
the NDF-image errors it reports and the quadrature of its deterministic reference."""

import sys
from pathlib import Path

import numpy as np
import pytest

from prefilter.glints import load
from prefilter.glints.bake import bake
from prefilter.glints.surface import surface
from prefilter.texture.procedural import normal_map

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import study_glints_reference as study  # noqa: E402

R, S, SR = 64, 1.0, 0.04


def _surf(nm, path):
    bake(nm, path, rank=16, ndf_res=R, block=16, support=S, cell=16, converge=0.0,
         intrinsic_roughness=SR, progress=False)
    # the render's query path (resampled pyramid, bilinear lookup) on the map's own roughness
    return surface(load(path), nm, intrinsic_roughness=SR)


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    d = tmp_path_factory.mktemp("acc")
    flakes = normal_map("flakes", size=32, seed=2, flake_size=6.0, rms_slope=0.3)
    flat = np.zeros((32, 32, 3))
    flat[..., 2] = 1.0
    return {"flakes": (flakes, _surf(flakes, d / "f.npz")),
            "flat": (flat, _surf(flat, d / "p.npz"))}


def test_compressed_ndf_keeps_the_glints_a_smooth_lobe_does_not(maps):
    """Footprints of a few flakes: the compressed query is close to the direct P-NDF image, the
    moment-matched Gaussian is not (a sum of separate peaks is not one lobe)."""
    nm, surf = maps["flakes"]
    c = np.array([[5.0, 7.0], [20.0, 11.0], [13.0, 26.0]])
    sp = np.array([1.2, 1.6, 2.0]) * surf.sigma_min
    comp, smooth = study.ndf_image_errors(nm, surf, c, sp, resolution=R, support=S)
    assert np.all(comp < 0.25), comp
    assert np.all(smooth > 0.4), smooth
    assert np.all(comp < 0.3 * smooth), (comp, smooth)


def test_flat_map_both_errors_vanish(maps):
    """A flat map's footprint NDF is one Gaussian lobe of the intrinsic roughness: the smooth lobe
    is exact (up to point values vs pixel averages) and so is the compressed query."""
    nm, surf = maps["flat"]
    c = np.array([[3.0, 4.0], [17.5, 30.0]])
    comp, smooth = study.ndf_image_errors(nm, surf, c, np.array([1.0, 3.0]) * surf.sigma_min,
                                          resolution=R, support=S)
    assert np.all(comp < 0.05), comp
    assert np.all(smooth < 0.05), smooth


@pytest.mark.parametrize("shrink", [1.0, 0.3])
def test_pixel_nodes_reproduce_the_pixel_ellipse(shrink):
    """``s_res^2 I`` plus the weighted node offsets mapped to texels is ``PIXEL_SIGMA^2 J J^T``
    (trapezoid over a Gaussian: the second moment to ~1e-3), with zero mean; ``shrink = 1``: the
    nodes lie on the major axis and an isotropic ``J`` gets a single node."""
    from prefilter.glints.render import PIXEL_SIGMA

    rng = np.random.default_rng(0)
    J = rng.normal(0.0, 3.0, (5, 2, 2))
    J[0] = [[2.0, 0.0], [0.0, -2.0]]
    pixel, off, w, s_res = study.pixel_nodes(J, shrink)
    np.testing.assert_allclose(np.bincount(pixel, w), 1.0, rtol=1e-12)
    t = np.einsum("nij,nj->ni", J[pixel], off)  # texel offsets of the nodes
    cov = np.zeros((5, 2, 2))
    np.add.at(cov, pixel, w[:, None, None] * t[:, :, None] * t[:, None, :])
    cov += s_res[:, None, None] ** 2 * np.eye(2)
    want = PIXEL_SIGMA**2 * np.einsum("nij,nkj->nik", J, J)
    np.testing.assert_allclose(cov, want, rtol=2e-3, atol=1e-9)
    np.testing.assert_allclose(np.stack([np.bincount(pixel, w * t[:, i]) for i in (0, 1)]), 0.0,
                               atol=1e-9)
    if shrink == 1.0:
        assert np.sum(pixel == 0) == 1 and np.allclose(off[pixel == 0], 0.0)
        d = off[pixel == 1]
        assert np.allclose(d[:, 0] * d[1, 1] - d[:, 1] * d[1, 0], 0.0)  # collinear
    else:
        assert np.sum(pixel == 0) > 9  # a 2D grid even for an isotropic footprint


def test_pick_pixels_takes_the_brightest_hits_then_random_ones():
    img = np.zeros((4, 5, 3))
    img[0, 0] = 9.0  # brightest, but not on the object
    img[1, 2], img[3, 4] = 5.0, 4.0
    hit = np.ones((4, 5), bool)
    hit[0, 0] = False
    p = study.pick_pixels(img, hit, 6, seed=1)
    assert list(p[:2]) == [7, 19] and p.size == 6
    assert 0 not in p and len(set(p)) == 6
    np.testing.assert_array_equal(p, study.pick_pixels(img, hit, 6, seed=1))
