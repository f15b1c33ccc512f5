"""`prefilter bake colormap`."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.integrate import quad
from scipy.stats import norm

from prefilter.cli import cli
from prefilter.texture.io import read_image, write_image


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
