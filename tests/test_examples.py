"""The shipped example scenes: one file per name, current with the code that builds them, each
loadable as ``example:NAME`` and renderable, listed by ``prefilter examples``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from prefilter.cli import cli
from prefilter.errors import PrefilterError
from prefilter.examples import EXAMPLES, PREFIX, names, path, resolve
from prefilter.render.scene import load_scene

REPO = Path(__file__).resolve().parents[1]
EXAMPLE_DIR = REPO / "src" / "prefilter" / "examples"

#: A method each example is meant for (rendered tiny below); glints bakes a pyramid (slow).
METHOD = {"showcase": "ltc", "showcase-far": "ltc-multiscale", "brushed-metal": "ltc-aniso",
          "multiscale-brushed": "ltc-multiscale", "multiscale-flakes": "ltc-multiscale",
          "leadr": "leadr-point", "colormap": "colormap-filtered", "glints": "glints",
          "plane-and-sphere": "ltc", "kettle": "path", "flake-panel": "path",
          "brushed-room": "path"}


def _generator():
    spec = importlib.util.spec_from_file_location("gen_examples",
                                                  REPO / "tools" / "gen_examples.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    return gen


def test_one_file_per_example():
    assert sorted(p.stem for p in EXAMPLE_DIR.glob("*.json")) == sorted(EXAMPLES)
    assert names() == list(EXAMPLES) and set(METHOD) == set(EXAMPLES)
    for name in names():
        assert path(name).is_file()
        assert resolve(PREFIX + name) == path(name)


def test_example_files_are_current():
    files = _generator().generate()
    stale = [n for n, text in files.items() if path(n).read_text(encoding="utf-8") != text]
    assert not stale, f"out of date: {stale}: run `python tools/gen_examples.py`"


def test_docs_example_is_shipped():
    assert json.loads(path("plane-and-sphere").read_text()) == _generator().docs_example()


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_example_loads_by_name(name):
    scene = load_scene(PREFIX + name)
    assert scene.camera.width > 0 and scene.objects
    assert load_scene(Path(PREFIX + name)).source == scene.source  # a Path works too


def test_unknown_example_names_the_choices():
    with pytest.raises(PrefilterError, match="example:NAME with NAME one of showcase, "):
        load_scene("example:nope")
    assert resolve("scene.json") == "scene.json" and resolve({"a": 1}) == {"a": 1}


def _tiny(name, width=12, height=8):
    sc = json.loads(path(name).read_text())
    sc["camera"].update(width=width, height=height)
    return load_scene(sc, base_dir=EXAMPLE_DIR)


@pytest.mark.parametrize("name", [n for n in EXAMPLES if n != "glints"])
def test_example_renders_tiny(name):
    from prefilter.render.driver import render

    img = render(_tiny(name), METHOD[name], spp=1, seed=0)
    assert img.shape == (8, 12, 3) and np.isfinite(img).all() and img.max() > 0


@pytest.mark.slow
def test_glints_example_renders_tiny(tmp_path, monkeypatch):
    from prefilter.render.driver import render

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path / "cache"))
    img = render(_tiny("glints"), "glints", spp=1, seed=0)
    assert np.isfinite(img).all() and img.max() > 0


def test_prefilter_examples_lists_one_line_each():
    result = CliRunner().invoke(cli, ["examples"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert [ln.split()[0] for ln in lines] == [PREFIX + n for n in EXAMPLES]
    assert all(len(ln.split()) > 3 for ln in lines)  # a description on each line


def test_prefilter_examples_name_prints_the_scene():
    result = CliRunner().invoke(cli, ["examples", "leadr"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output) == json.loads(path("leadr").read_text())


def test_prefilter_render_example(tmp_path):
    """`prefilter render example:NAME` reads the shipped file (no file of that name exists)."""
    out = tmp_path / "brushed.npy"
    result = CliRunner().invoke(cli, ["render", "example:brushed-metal", "--method", "ltc-aniso",
                                      "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    img = np.load(out)
    assert img.shape == (120, 192, 3) and np.isfinite(img).all()


def test_examples_are_package_data():
    tomllib = pytest.importorskip("tomllib")
    data = tomllib.loads((REPO / "pyproject.toml").read_text())
    globs = data["tool"]["setuptools"]["package-data"]["prefilter"]
    src = REPO / "src" / "prefilter"
    shipped = {p for g in globs for p in src.glob(g)}
    assert set(EXAMPLE_DIR.glob("*.json")) <= shipped
