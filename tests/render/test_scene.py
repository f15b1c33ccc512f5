"""Scene files: the documented example loads, broken scenes give clear field-path errors,
textures resolve relative to the scene file and load lazily."""

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.render import gbuffer, load_scene
from prefilter.texture import encode_normals, normal_map, write_image

DOC = Path(__file__).resolve().parents[2] / "docs" / "scenes.md"


def _example() -> dict:
    text = DOC.read_text()
    return json.loads(re.search(r"```json\n(.*?)```", text, re.S).group(1))


def test_documented_example_loads_and_renders():
    s = load_scene(_example())
    assert s.camera.width == 320 and s.camera.fov == 40.0
    plane, sphere = s.objects
    assert plane.type == "plane" and sphere.type == "sphere"
    assert plane.material.alpha_x == 0.15 and np.allclose(sphere.material.f0, 0.04)
    assert np.allclose(plane.tangent, [1, 0, 0]) and np.allclose(plane.normal, [0, 1, 0])
    ls = s.light_set()
    assert len(ls.quads) == 1 and len(ls.directionals) == 1
    # the quad faces the plane in front of it (+z), towards the camera
    assert ls.quads[0].normal @ np.array([0, 0, 1.0]) > 0.99
    n = plane.material.normal_map.load()
    assert n.shape == (256, 256, 3) and np.allclose(np.linalg.norm(n, axis=-1), 1)
    assert plane.material.normal_map.mip().n_levels == 9
    assert s.to_dict() == _example()
    g = gbuffer(s.__class__(s.camera.with_size(32, 18), s.objects, s.lights))
    assert g.hit.any()


def test_defaults_and_alpha_shorthand():
    s = load_scene({"camera": {"origin": [0, 1, 2], "target": [0, 0, 0], "fov": 30,
                               "width": 4, "height": 4},
                    "objects": [{"type": "sphere", "radius": 1, "material": {"alpha": 0.2}}]})
    m = s.objects[0].material
    assert m.alpha_x == m.alpha_y == 0.2 and np.allclose(m.f0, 1) and np.allclose(m.base_color, 0)
    assert s.lights == () and m.normal_map is None


def _broken(path, value):
    d = copy.deepcopy(_example())
    keys = re.findall(r"[^.\[\]]+", path)
    obj = d
    for k in keys[:-1]:
        obj = obj[int(k)] if k.isdigit() else obj[k]
    last = keys[-1]
    if value is KeyError:
        del obj[last]
    elif last.isdigit():
        obj[int(last)] = value
    else:
        obj[last] = value
    return d


@pytest.mark.parametrize("path, value, message", [
    ("objects.0.material.alpha_x", "a",
     'objects[0].material.alpha_x: expected a number in [0.001, 1], got "a"'),
    ("objects.1.material.alpha", 2.0, "objects[1].material.alpha: expected a number in [0.001, 1]"),
    ("objects.1.radius", -1, "objects[1].radius: expected a number > 0, got -1"),
    ("objects.0.type", "cube",
     'objects[0].type: expected one of "plane", "sphere", "mesh", got "cube"'),
    ("objects.0.colour", 1, "objects[0].colour: unknown field"),
    ("camera.fov", KeyError, "camera.fov: required field is missing"),
    ("camera.width", 12.5, "camera.width: expected an integer"),
    ("camera.origin", [0, 1], "camera.origin: expected a list of 3 numbers"),
    ("camera.up", [0, -1.2, -6], "camera.up: expected a vector not parallel"),
    ("lights.0.vertices", [[0, 0, 0]] * 3, "lights[0].vertices: expected a list of 4 corners"),
    ("lights.0.vertices", [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]],
     "lights[0].vertices: quad light vertices: expected 4 coplanar corners"),
    ("lights.1.irradiance", [1, -1, 1], "lights[1].irradiance: expected a list of 3 numbers >= 0"),
    ("lights.1.type", "spot", "lights[1].type: expected one of"),
    ("objects.0.material.normal_map.procedural", "plaid",
     'objects[0].material.normal_map.procedural: expected one of "gaussian"'),
    ("objects.0.material.normal_map.rms", 0.3,
     "objects[0].material.normal_map.rms: unknown field"),
    ("objects.0.material.normal_map", "missing.png",
     "objects[0].material.normal_map.path: file not found"),
    ("objects.0.material.normal_map", "maps/bumps.gif",
     "objects[0].material.normal_map.path: expected a .png/.exr/.npy file"),
    ("objects", {}, "objects: expected a list"),
])
def test_broken_scenes_name_the_field(path, value, message):
    with pytest.raises(PrefilterError) as e:
        load_scene(_broken(path, value))
    assert message in str(e.value)


def test_procedural_values_checked_at_load_with_path():
    d = _broken("objects.0.material.normal_map.rms_slope", -3)
    with pytest.raises(PrefilterError, match=r"objects\[0\]\.material\.normal_map\.rms_slope"):
        load_scene(d)  # before any render, not on first use


def test_file_errors(tmp_path):
    with pytest.raises(PrefilterError, match="scene file not found"):
        load_scene(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"camera": {,}}')
    with pytest.raises(PrefilterError, match=r"bad.json: invalid JSON at line 1, column 13"):
        load_scene(bad)
    with pytest.raises(PrefilterError, match="scene: expected a JSON file path or a dict"):
        load_scene(42)


def test_texture_paths_are_relative_to_the_scene_file(tmp_path):
    n = normal_map("gaussian", 32, 4, rms_slope=0.4, corr_length=3.0)
    (tmp_path / "maps").mkdir()
    write_image(tmp_path / "maps" / "n.png", encode_normals(n, "directx"), bits=16)
    d = _example()
    d["objects"][0]["material"]["normal_map"] = {"path": "maps/n.png", "convention": "directx"}
    (tmp_path / "scene.json").write_text(json.dumps(d))
    s = load_scene(tmp_path / "scene.json")
    ref = s.objects[0].material.normal_map
    assert ref.path == (tmp_path / "maps" / "n.png").resolve()
    assert np.abs(ref.load() - n).max() < 1e-4
    assert ref.load() is ref.load()  # cached
