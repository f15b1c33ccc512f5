"""``prefilter bake roughness``: outputs, flags and one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from prefilter.cli import main
from prefilter.texture.io import read_image, write_image
from prefilter.texture.normalmap import encode_normals
from prefilter.texture.procedural import normal_map


def _run(capfd, *args):
    capfd.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["bake", "roughness", *map(str, args)])
    out, err = capfd.readouterr()
    return (exc.value.code or 0), out, err


def test_procedural_map_all_outputs(capfd, tmp_path):
    rc, out, err = _run(capfd, "procedural:gaussian:16:1", "-o", tmp_path, "--method", "lean",
                        "-r", "0.4")
    assert rc == 0, err
    names = {p.name for p in tmp_path.iterdir()}
    assert {"roughness.dds", "roughness.ktx2", "roughness.json", "roughness_L0.exr",
            "roughness_L4.png"} <= names and "roughness_L5.exr" not in names
    meta = json.loads((tmp_path / "roughness.json").read_text())
    assert meta["method"] == "lean" and meta["roughness"] == "perceptual"
    assert meta["levels"][-1] == [1, 1]
    # perceptual output: level 0 is the constant roughness itself
    assert np.allclose(read_image(tmp_path / "roughness_L0.exr"), 0.4, atol=1e-3)


def test_file_map_roughness_map_alpha_output_and_orm(capfd, tmp_path):
    n = normal_map("flakes", 8, seed=1)
    write_image(tmp_path / "n.png", encode_normals(n), bits=16)
    rough = np.full((8, 8), 0.5)
    write_image(tmp_path / "r.exr", rough)
    out = tmp_path / "out"
    rc, _, err = _run(capfd, tmp_path / "n.png", "-o", out, "-m", tmp_path / "r.exr",
                      "--output-roughness", "alpha", "--pack-orm", "-f", "exr", "-f", "ktx2")
    assert rc == 0, err
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [f"orm_L{k}.exr" for k in range(4)] + ["orm.ktx2", "roughness.json"])
    level0 = read_image(out / "orm_L0.exr")
    assert np.allclose(level0[..., 1], 0.25, atol=1e-3)  # alpha = 0.5^2 in green
    assert np.allclose(level0[..., 0], 1.0) and np.allclose(level0[..., 2], 0.0)


@pytest.mark.parametrize("args,message", [
    (["{tmp}/missing.png"], "NORMALMAP: no such file"),
    (["{tmp}/npot.png"], "npot.png: expected power-of-two height and width"),
    (["{tmp}/photo.png"], "photo.png: not a normal map"),
    (["procedural:gaussian:16", "-m", "{tmp}/missing.exr"], "--roughness-map: no such file"),
    (["procedural:gaussian:16", "-m", "{tmp}/r8.exr"], "normal map's size 16 x 16, got 8 x 8"),
    (["procedural:gaussian:16", "-r", "0.2", "-m", "{tmp}/r8.exr"], "expected one of them"),
])
def test_bad_input_is_one_line(capfd, tmp_path, args, message):
    write_image(tmp_path / "npot.png", encode_normals(normal_map("gaussian", 16)[:12]))
    write_image(tmp_path / "photo.png", np.random.default_rng(0).random((16, 16, 3)))
    write_image(tmp_path / "r8.exr", np.full((8, 8), 0.5))
    rc, _, err = _run(capfd, *[a.format(tmp=tmp_path) for a in args], "-o", tmp_path / "o")
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("prefilter: error: ") and message in err
