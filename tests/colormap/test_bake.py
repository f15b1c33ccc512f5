"""`prefilter bake colormap`, the GLSL snippet and its Python twin."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.integrate import quad
from scipy.stats import norm

from prefilter.cli import cli
from prefilter.colormap import prefilter_table
from prefilter.colormap.glsl import glsl_lookup_twin, glsl_snippet, glsl_texture_twin
from prefilter.texture.io import read_image, write_image


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


def test_bake_command_writes_table_and_metadata(tmp_path):
    c = np.linspace(0.0, 1.0, 32)[None, :, None] * np.array([1.0, 0.5, 0.0])
    c[..., 1] = (np.arange(32) % 8 < 4)[None, :]  # a stripy channel: a very non-linear map
    src = tmp_path / "map.png"
    write_image(src, np.repeat(c, 4, axis=0), bits=16)
    out = tmp_path / "table.exr"
    res = CliRunner().invoke(cli, ["bake", "colormap", str(src), "--sigma-max", "0.1", "--range",
                                   "0", "2", "--size", "32", "--linear", "-o", str(out),
                                   "--glsl", str(tmp_path / "lookup.glsl")])
    assert res.exit_code == 0, res.output
    table = read_image(out)
    meta = json.loads((tmp_path / "table.json").read_text())
    assert table.shape == (32, 32, 3)
    assert meta["value_range"] == [0.0, 2.0] and meta["sigma_max"] == 0.1
    assert meta["edge"] == "clamp" and meta["n_sigma"] == 32
    q = np.round(c[0] * 65535) / 65535  # the colour map as stored in the 16-bit PNG
    np.testing.assert_allclose(table[0], q, atol=1e-6)  # row 0: the map itself (float32)
    # one blurred entry against quadrature of the linearly interpolated map
    centres = (np.arange(32) + 0.5) / 16
    j, i = 20, 9
    s, m = 0.1 * j / 31, centres[i]
    ref = quad(lambda x: np.interp(m + x, centres, q[:, 1]) * norm.pdf(x, 0, s), -8 * s, 8 * s,
               points=np.sort(centres - m)[np.abs(centres - m) < 8 * s], limit=500)[0]
    assert table[j, i, 1] == pytest.approx(ref, abs=1e-6)
    assert "colormapFiltered" in (tmp_path / "lookup.glsl").read_text()


def test_bake_command_rejects_bad_input(tmp_path):
    bad = tmp_path / "x.txt"
    bad.write_text("no")
    res = CliRunner().invoke(cli, ["bake", "colormap", str(bad), "--sigma-max", "0.1",
                                   "-o", str(tmp_path / "t.exr")])
    assert res.exit_code != 0
    src = tmp_path / "m.png"
    write_image(src, np.zeros((1, 8, 3)))
    res = CliRunner().invoke(cli, ["bake", "colormap", str(src), "--sigma-max", "-1",
                                   "-o", str(tmp_path / "t.exr")])
    assert res.exit_code != 0 and "sigma_max" in str(res.exception) + res.output


def test_glsl_snippet_writes_float_literals_for_whole_numbers():
    # GLSL ES 3.00 has no implicit int -> float conversion: `const float x = 2;` does not compile
    import re

    from prefilter.colormap.glsl import glsl_snippet

    src = glsl_snippet({"value_range": [0, 4], "edge": "mirror", "sigma_max": 2, "n_sigma": 64})
    for line in src.splitlines():
        if line.startswith("const float") or line.startswith("const vec"):
            for number in re.findall(r"(?<![\w.])-?\d+(?:\.\d*)?(?:e-?\d+)?(?![\w.])",
                                     line.split("=", 1)[1]):
                assert "." in number or "e" in number, (line, number)
