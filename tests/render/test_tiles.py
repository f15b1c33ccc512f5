"""Bands of image rows: a band rendered alone is those rows of the whole image, byte for byte,
and a banded render resumes from its checkpointed bands."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.render.driver import render
from prefilter.render.tiles import render_tiled, tile_bounds

#: Small scene with a quad and a directional light (the reference's staged NumPy path).
SCENE = {
    "camera": {"origin": [0, 1.2, 4], "target": [0, 0, -2], "up": [0, 1, 0], "fov": 40,
               "width": 16, "height": 12},
    "objects": [
        {"type": "plane", "center": [0, 0, -10], "normal": [0, 1, 0], "tangent": [1, 0, 0],
         "size": [20, 30], "material": {"alpha": 0.2, "base_color": 0.1, "f0": 0.5}},
        {"type": "sphere", "center": [0.5, 0.5, -3], "radius": 0.8,
         "material": {"alpha": 0.3, "base_color": [0.2, 0.3, 0.6], "f0": 0.04}},
    ],
    "lights": [{"type": "quad", "vertices": [[-2, 0.5, -8], [2, 0.5, -8], [2, 3, -8],
                                             [-2, 3, -8]], "radiance": [4, 4, 4]},
               {"type": "directional", "direction": [0, -1, -1], "irradiance": 0.5}],
}


def test_tile_bounds_cover_the_image():
    assert tile_bounds(10, 4) == [(0, 4), (4, 8), (8, 10)]


@pytest.mark.parametrize("method,spp", [("ltc", 1), ("reference", 4)])
def test_a_band_is_its_rows_of_the_whole_image(method, spp):
    whole = render(SCENE, method, spp=spp, seed=2)
    # chunks of 3 rows: bands start and end inside chunks
    band = render(SCENE, method, spp=spp, seed=2, rows=(4, 9), chunk_samples=3 * 16 * spp)
    assert band.tobytes() == whole[4:9].tobytes()


def test_rows_out_of_the_image_are_refused():
    with pytest.raises(PrefilterError, match=r"rows: expected \(r0, r1\)"):
        render(SCENE, "ltc", rows=(5, 13))


def test_banded_render_resumes_from_its_checkpoints(tmp_path, monkeypatch):
    import prefilter.render.tiles as tiles
    from prefilter.fileio import save_npz_atomic

    whole = render(SCENE, "reference", spp=4, seed=1)
    out = tmp_path / "img.npy"

    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    # killed after its bands were saved, before the image was written: the parts stay
    with monkeypatch.context() as m:
        m.setattr(tiles, "write_image", killed)
        with pytest.raises(KeyboardInterrupt):
            render_tiled(SCENE, "reference", out=out, spp=4, seed=1, tile_rows=5)
    parts = sorted((tmp_path / "img.npy.parts").glob("*.npz"))
    assert len(parts) == len(tile_bounds(12, 5))
    # the rerun takes the saved bands as they are: a band marked in its part shows up unchanged
    marked = np.full((5, 16, 3), 7.0, np.float32)
    save_npz_atomic(parts[1], image=marked)
    image = render_tiled(SCENE, "reference", out=out, spp=4, seed=1, tile_rows=5)
    assert image[5:10].tobytes() == marked.tobytes()
    assert image[:5].tobytes() == whole[:5].tobytes()
    assert image[10:].tobytes() == whole[10:].tobytes()
    assert not (tmp_path / "img.npy.parts").exists()
