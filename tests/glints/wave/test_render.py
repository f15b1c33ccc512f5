"""Render methods ``glints-wave`` / ``glints-wave-direct``: quad lights by light sampling, the
lights they accept."""

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


def test_environment_lights_are_rejected(cache):
    with pytest.raises(PrefilterError, match="expected point, directional or untextured quad"):
        render(_scene("environment"), "glints-wave")
