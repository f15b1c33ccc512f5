"""The GLSL snippet, and a float32 emulation of its ``texture()`` call checked against
:meth:`prefilter.colormap.table.ColormapTable.lookup`."""

import re

import numpy as np
import pytest

from prefilter.colormap import prefilter_table
from prefilter.colormap.glsl import GLSL_WRAP, glsl_snippet


def gl_wrap(i: np.ndarray, size: int, mode: str) -> np.ndarray:
    """Texel index wrapping of OpenGL 4.6, section 8.14.2 (table 8.20)."""
    if mode == "GL_REPEAT":
        return np.mod(i, size)
    if mode == "GL_MIRRORED_REPEAT":
        a = np.mod(i, 2 * size) - size
        return (size - 1) - np.where(a >= 0, a, -(1 + a))
    if mode == "GL_CLAMP_TO_EDGE":
        return np.clip(i, 0, size - 1)
    raise ValueError(mode)


def glsl_texture_twin(image, u, v, wrap_s: str, wrap_t: str = "GL_CLAMP_TO_EDGE") -> np.ndarray:
    """``texture(sampler, vec2(u, v))`` of a ``GL_LINEAR`` 2D sampler on ``image (H, W, C)``
    (row ``r`` at ``t = (r + 0.5) / H``), ``(..., C)``, evaluated in float32 as a GPU would."""
    img = np.asarray(image, dtype=np.float32)
    h, w = img.shape[:2]
    x = np.asarray(u, dtype=np.float32) * np.float32(w) - np.float32(0.5)
    y = np.asarray(v, dtype=np.float32) * np.float32(h) - np.float32(0.5)
    x, y = np.broadcast_arrays(x, y)
    i0, j0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    a, b = (x - np.floor(x))[..., None], (y - np.floor(y))[..., None]
    c0, c1 = gl_wrap(i0, w, wrap_s), gl_wrap(i0 + 1, w, wrap_s)
    r0, r1 = gl_wrap(j0, h, wrap_t), gl_wrap(j0 + 1, h, wrap_t)
    return ((1 - a) * (1 - b) * img[r0, c0] + a * (1 - b) * img[r0, c1]
            + (1 - a) * b * img[r1, c0] + a * b * img[r1, c1])


def glsl_lookup_twin(image, metadata: dict, mean, sigma) -> np.ndarray:
    """Python twin of the snippet's ``colormapFiltered(mean, sigma)``, shape ``(..., C)``."""
    m = np.asarray(mean, np.float32)
    s = np.asarray(sigma, np.float32)
    lo, hi = (np.float32(x) for x in metadata["value_range"])
    smax, ns = np.float32(metadata["sigma_max"]), np.float32(metadata["n_sigma"])
    u = (m - lo) / (hi - lo)
    v = (np.clip(s / smax, 0, 1) * (ns - 1) + np.float32(0.5)) / ns
    return glsl_texture_twin(image, u, v, GLSL_WRAP[metadata["edge"]])


@pytest.mark.parametrize("edge", ["clamp", "mirror", "periodic"])
def test_glsl_twin_matches_lookup(edge):
    rng = np.random.default_rng(7)
    t = prefilter_table(rng.random((64, 3)), (-1.0, 3.0), 0.8, size=64, n_sigma=33, edge=edge)
    m = rng.uniform(-3.0, 5.0, 2000) if edge != "clamp" else rng.uniform(-1.5, 3.5, 2000)
    s = rng.uniform(0.0, 1.0, 2000)  # includes sigma > sigma_max (clamped by both)
    got = glsl_lookup_twin(t.table.astype(np.float32), t.metadata(), m, s)
    np.testing.assert_allclose(got, t.lookup(m, s), atol=2e-5)


def test_gl_wrap_modes_follow_the_specification():
    img = np.arange(4.0)[None, :, None]  # one row: texels 0 1 2 3
    u = (np.array([-2.0, -1.0, 4.0, 5.0]) + 0.5) / 4  # texel centres outside [0, 4)
    np.testing.assert_allclose(glsl_texture_twin(img, u, 0.5, "GL_REPEAT")[:, 0], [2, 3, 0, 1])
    np.testing.assert_allclose(glsl_texture_twin(img, u, 0.5, "GL_MIRRORED_REPEAT")[:, 0],
                               [1, 0, 3, 2])
    np.testing.assert_allclose(glsl_texture_twin(img, u, 0.5, "GL_CLAMP_TO_EDGE")[:, 0],
                               [0, 0, 3, 3])


def test_snippet_carries_the_table_layout():
    t = prefilter_table(np.zeros((8, 3)), (-2.0, 5.0), 0.75, size=8, edge="mirror")
    code = glsl_snippet(t.metadata())
    assert "GL_MIRRORED_REPEAT" in code and "vec2(-2.0, 5.0)" in code and "0.75" in code
    assert code.count("{") == code.count("}")


def test_glsl_snippet_writes_float_literals_for_whole_numbers():
    # GLSL ES 3.00 has no implicit int -> float conversion: `const float x = 2;` does not compile
    src = glsl_snippet({"value_range": [0, 4], "edge": "mirror", "sigma_max": 2, "n_sigma": 64})
    for line in src.splitlines():
        if line.startswith("const float") or line.startswith("const vec"):
            for number in re.findall(r"(?<![\w.])-?\d+(?:\.\d*)?(?:e-?\d+)?(?![\w.])",
                                     line.split("=", 1)[1]):
                assert "." in number or "e" in number, (line, number)
