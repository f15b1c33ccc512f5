"""The ``ltc-aniso`` method with textured quad lights: a constant texture is the untextured light
(the normalised prefiltered pyramid of a constant is that constant), and a two-colour texture
moves the image towards the Monte Carlo reference of the same textured light."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.ltc.aniso.demo import demo_scene
from prefilter.ltc.aniso.render import shade_ltc_aniso
from prefilter.render import load_scene, render
from prefilter.render.lights import LightSet, QuadLight
from prefilter.render.lighttex import LightTexture, TexturedQuad
from prefilter.texture.io import write_image


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    d = tmp_path_factory.mktemp("aniso_textured")
    write_image(d / "const.exr", np.broadcast_to([0.5, 0.25, 1.0], (4, 6, 3)).copy())
    split = np.zeros((8, 8, 3))
    split[:, :4] = [1.0, 0.2, 0.2]  # red towards v0, blue towards v1 (texture u)
    split[:, 4:] = [0.2, 0.2, 1.0]
    write_image(d / "split.exr", split)
    return d


def _scene(texture=None, radiance=6.0, size=(32, 24)):
    sc = demo_scene(*size)
    sc["lights"][0]["radiance"] = radiance
    if texture is not None:
        sc["lights"][0]["texture"] = texture
    return sc


def test_constant_texture_equals_untextured_light(assets, table):
    c = np.array([0.5, 0.25, 1.0])
    img = render(load_scene(_scene("const.exr"), base_dir=assets), "ltc-aniso", table=table)
    plain = render(load_scene(_scene(radiance=(6.0 * c).tolist())), "ltc-aniso", table=table)
    assert plain.max() > 0.1
    np.testing.assert_allclose(img, plain, rtol=1e-5, atol=1e-7)


def test_constant_texture_at_the_shader(table):
    # grazing, back-facing (normal-mapped) and anisotropic samples, one-channel texture
    rng = np.random.default_rng(5)
    n = 500
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)) * 0.3 + np.eye(3))
    pos = rng.normal(size=(n, 3)) * 0.3
    view = rng.normal(size=(n, 3))
    view /= np.linalg.norm(view, axis=-1, keepdims=True)
    v = np.array([[-1.0, -1, 1.5], [1, -1, 1.5], [1, 1, 1.5], [-1, 1, 1.5]])[::-1].copy()
    args = (pos, q[:, :, 0], q[:, :, 1], q[:, :, 2], view, rng.uniform(0.01, 1, n),
            rng.uniform(0.01, 1, n), rng.random((n, 3)), rng.random((n, 3)))
    tq = TexturedQuad(v, [1.0, 2.0, 3.0], LightTexture(np.full((3, 3), 0.4)))
    tex = shade_ltc_aniso(*args, LightSet(), table, (tq,))
    plain = shade_ltc_aniso(*args, LightSet(quads=(QuadLight(v, [0.4, 0.8, 1.2]),)), table)
    assert np.count_nonzero(plain.sum(-1)) > n // 3
    np.testing.assert_allclose(tex, plain, rtol=1e-9, atol=1e-12)


def test_two_colour_texture_tracks_the_reference(assets, table):
    """The prefiltered lookup of a red|blue light is closer to the reference of that light than
    the untextured light of the same mean colour is."""
    from prefilter.render.metrics import rmse

    s = load_scene(_scene("split.exr", size=(48, 36)), base_dir=assets)
    ref = render(s, "reference", spp=256, seed=1)
    img = render(s, "ltc-aniso", table=table)
    mean = render(load_scene(_scene(radiance=[3.6, 1.2, 3.6], size=(48, 36))), "ltc-aniso",
                  table=table)
    assert np.all(np.isfinite(img)) and np.all(img >= 0)
    assert rmse(img, ref) < 0.9 * rmse(mean, ref), (rmse(img, ref), rmse(mean, ref))
