"""Render methods ``glints-wave`` / ``glints-wave-direct``: quad and environment lights by light
sampling, the lights they accept."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.glints.render import measurement_scene
from prefilter.render.driver import render
from prefilter.render.scene import load_scene

HF = "procedural:noise:32:1"


def _scene(lights, distance=2.0):
    sc = measurement_scene(distance, "gaussian", width=24, height=18, lights=lights)
    sc["extras"] = {"glints_wave": {"heightfield": HF}}
    return load_scene(sc)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path / "cache"))


def test_quad_light_carries_the_point_lights_energy(cache):
    """The measurement quad (side 0.16 d, the point light's on-axis intensity, at its place)
    lights the plane like the point light: frame means within 3 % (light sampling, 8 samples,
    fixed seed), lighting about the same pixels (the quad's half vectors spread wider)."""
    quad = render(_scene("quad"), "glints-wave-direct")
    point = render(_scene("point"), "glints-wave-direct")
    assert quad.mean() == pytest.approx(point.mean(), rel=0.03)
    lit_q, lit_p = quad.sum(-1) > 0, point.sum(-1) > 0
    assert (lit_q == lit_p).mean() > 0.9
    again = render(_scene("quad"), "glints-wave-direct")
    np.testing.assert_array_equal(quad, again)  # deterministic samples


def test_textured_quads_are_rejected(cache, tmp_path):
    from prefilter.glints.render import measurement_scene as ms

    sc = ms(2.0, "gaussian", width=8, height=6, lights="quad")
    np.save(tmp_path / "t.npy", np.ones((4, 4, 3)))
    sc["lights"][0]["texture"] = str(tmp_path / "t.npy")
    sc["extras"] = {"glints_wave": {"heightfield": HF}}
    with pytest.raises(PrefilterError, match="untextured quad or environment lights, got a "
                                             "textured quad"):
        render(load_scene(sc), "glints-wave")


def test_environment_sampling_integrates_lambert_under_a_constant_sky():
    """Light sampling of a constant environment (radiance 2) gives Lambert's ``base L`` when the
    NDF is 0 (the estimator's weights ``cos / p`` integrate the hemisphere): within 4 sigma."""
    from prefilter.render.pathtrace import EnvironmentSampler
    from prefilter.glints.wave.render import ENV_SAMPLES, environment_rgb

    rng = np.random.default_rng(0)
    N = 4000
    frame = (np.tile([1.0, 0, 0], (N, 1)), np.tile([0, 0, -1.0], (N, 1)),
             np.tile([0, 1.0, 0], (N, 1)))
    wo = np.tile([0.0, 0.6, 0.8], (N, 1))
    env = EnvironmentSampler(np.full((16, 32, 3), 2.0))
    base = np.array([0.5, 0.25, 0.1])
    out = environment_rgb(lambda c, sp, s: np.zeros((len(s), 3)), np.zeros((N, 2)),
                          np.full(N, 4.0), wo, frame, env, 0.04, base,
                          rng.random((N, 3 * ENV_SAMPLES)))
    mean, err = out.mean(0), out.std(0) / np.sqrt(N)
    assert np.all(np.abs(mean - 2.0 * base) < 4 * err + 1e-12), (mean, err)


def test_environment_light_renders_both_methods_alike(cache):
    a = render(_scene("environment", 8.0), "glints-wave-direct")
    b = render(_scene("environment", 8.0), "glints-wave")
    assert np.all(np.isfinite(a)) and a.mean() > 0
    assert b.mean() == pytest.approx(a.mean(), rel=0.03)
