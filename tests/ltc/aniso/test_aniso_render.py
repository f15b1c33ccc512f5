"""The ``ltc-aniso`` render method on a small version of the demo scene, against the reference."""

import numpy as np
import pytest

from prefilter.ltc.aniso.demo import demo_scene
from prefilter.render.methods import available
from prefilter.render.driver import render


def test_registered():
    assert "ltc-aniso" in available()


def test_ltc_aniso_close_to_reference():
    """Brushed metal: ltc-aniso tracks the Monte Carlo reference; the isotropic ltc method (mean
    roughness) does not."""
    from prefilter.errors import TableFileError
    from prefilter.render.metrics import rmse

    scene = demo_scene(48, 36)
    ref = render(scene, "reference", spp=64, seed=1)
    img = render(scene, "ltc-aniso")
    assert img.shape == (36, 48, 3) and np.all(np.isfinite(img)) and np.all(img >= 0)
    lit = ref.mean(-1) > 0.05
    assert lit.sum() > 50
    # mean radiance over the lit pixels within 10 %
    assert img[lit].mean() == pytest.approx(ref[lit].mean(), rel=0.1)
    try:
        iso = render(scene, "ltc")
    except TableFileError:
        pytest.skip("isotropic table not available")
    assert rmse(img, ref) < 0.5 * rmse(iso, ref)
