"""Mesh loading (OBJ, PLY, glTF through trimesh), transforms, tangents and bad input."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("embreex")

from mesh_assets import quad_arrays, uv_sphere_arrays, write_quad, write_uv_sphere  # noqa: E402

from prefilter.errors import PrefilterError  # noqa: E402
from prefilter.render import load_scene  # noqa: E402
from prefilter.render.mesh import load_mesh, transform_matrix, vertex_tangents  # noqa: E402

CAM = {"origin": [0, 2, 3], "target": [0, 0, 0], "fov": 40, "width": 8, "height": 8}


def scene(obj):
    return load_scene({"camera": CAM, "objects": [obj]})


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb", ".gltf"])
def test_formats_read_the_same_quad(tmp_path, suffix):
    """Every format gives the quad's positions, normals and renderer-space UVs (the v flip of
    the OBJ convention undone; glTF's own flip undone by trimesh)."""
    v, f, n, uv = quad_arrays()
    d = load_mesh(write_quad(tmp_path / f"quad{suffix}"))
    order = [int(np.argmin(np.linalg.norm(d.vertices - p, axis=1))) for p in v]
    np.testing.assert_allclose(d.vertices[order], v, atol=1e-6)
    np.testing.assert_allclose(d.uv[order], uv, atol=1e-6)
    np.testing.assert_allclose(d.normals[order], n, atol=1e-6)
    assert len(d.faces) == 2


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb", ".gltf"])
def test_formats_keep_the_files_normals(tmp_path, suffix):
    """The UV sphere's radial normals as stored (float32 files), not recomputed from faces
    (which would tilt the one-triangle pole vertices)."""
    v, f, n, uv = uv_sphere_arrays(8, 16)
    d = load_mesh(write_uv_sphere(tmp_path / f"s{suffix}", 8, 16))
    np.testing.assert_allclose(d.vertices, v, atol=1e-6)
    np.testing.assert_allclose(d.normals, n, atol=1e-6)
    np.testing.assert_allclose(d.uv, uv, atol=1e-6)
    np.testing.assert_array_equal(d.faces, f)


def test_quad_tangents_are_the_plane_frame(tmp_path):
    """The analytic plane's frame: tangent +x (+u), bitangent -z (+v) = n x t, w = +1."""
    d = load_mesh(write_quad(tmp_path / "quad.obj"))
    np.testing.assert_allclose(d.tangents, np.tile([1.0, 0.0, 0.0, 1.0], (4, 1)), atol=1e-12)


def test_mirrored_uvs_flip_the_handedness():
    """u mirrored: t = -x and, as v still runs along -z, w = -1 (b = w n x t = -z)."""
    v, f, n, uv = quad_arrays()
    t = vertex_tangents(v, f, n, np.stack([1.0 - uv[:, 0], uv[:, 1]], -1))
    np.testing.assert_allclose(t, np.tile([-1.0, 0.0, 0.0, -1.0], (4, 1)), atol=1e-12)
    b = t[:, 3:] * np.cross(n, t[:, :3])
    np.testing.assert_allclose(b, np.tile([0.0, 0.0, -1.0], (4, 1)), atol=1e-12)


def test_sphere_tangents_are_d_position_d_u():
    """On a UV sphere the tangent is the unit d p / d u = (-sin phi, 0, cos phi) and the
    bitangent d p / d v (towards the south pole): exact off the seam and the poles (the
    neighbouring triangles are symmetric), within half a segment on the seam, whose split
    vertices see the triangles of one side only (as MikkTSpace, which does not weld across UV
    seams)."""
    nt, nph = 32, 64
    v, f, n, uv = uv_sphere_arrays(nt, nph)
    t = vertex_tangents(v, f, n, uv)
    phi, theta = 2 * np.pi * uv[:, 0], np.pi * uv[:, 1]
    inner = (theta > 0.5 * np.pi / nt) & (theta < np.pi - 0.5 * np.pi / nt)  # not the poles
    seam = (uv[:, 0] == 0.0) | (uv[:, 0] == 1.0)
    t_exact = np.stack([-np.sin(phi), np.zeros_like(phi), np.cos(phi)], -1)
    b_exact = np.stack([np.cos(theta) * np.cos(phi), -np.sin(theta),
                        np.cos(theta) * np.sin(phi)], -1)
    b = t[:, 3:] * np.cross(n, t[:, :3])
    dphi = 2 * np.pi / nph
    for got, exact in ((t[:, :3], t_exact), (b, b_exact)):
        err = np.linalg.norm(got - exact, axis=1)
        assert err[inner & ~seam].max() < 1e-12
        assert err[inner].max() < 0.5 * dphi
    assert np.all(t[inner, 3] == 1.0)


def test_transform_moves_vertices_and_normals(tmp_path):
    """Object {translate, rotate, scale}: vertices by T R S, normals by the inverse transpose
    (a non-uniform scale keeps them perpendicular to the surface)."""
    p = write_uv_sphere(tmp_path / "s.ply", 8, 16)
    s = scene({"type": "mesh", "file": str(p),
               "transform": {"translate": [1, 2, 3], "rotate": [0, 90, 0], "scale": [2, 1, 1]}})
    d = s.objects[0].data
    m = transform_matrix([1, 2, 3], [0, 90, 0], [2, 1, 1])
    base = load_mesh(p)
    np.testing.assert_allclose(d.vertices, base.vertices @ m[:3, :3].T + [1, 2, 3], atol=1e-12)
    # the ellipsoid's normal at x: grad of |S^-1 R^-1 (x - c)|^2
    q = (d.vertices - [1, 2, 3]) @ np.linalg.inv(m[:3, :3]).T
    g = q @ np.linalg.inv(m[:3, :3])
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    assert np.min(np.sum(g * d.normals, 1)) > 0.999999
    matrix = scene({"type": "mesh", "file": str(p), "transform": m.tolist()}).objects[0].data
    np.testing.assert_allclose(matrix.vertices, d.vertices, atol=1e-12)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(PrefilterError, match=r"objects\[0\]\.file: mesh file not found"):
        scene({"type": "mesh", "file": str(tmp_path / "none.obj")})


@pytest.mark.parametrize("name, data", [("bad.ply", b"ply\nformat binary_little_endian 1.0\n"
                                                    b"element vertex 100\nproperty float x\n"
                                                    b"end_header\n\x00\x01"),
                                        ("bad.glb", b"xxxx"),
                                        ("empty.obj", b"# nothing\n")])
def test_unreadable_or_empty_file_is_named(tmp_path, name, data):
    (tmp_path / name).write_bytes(data)
    with pytest.raises(PrefilterError, match=rf"objects\[0\]\.file: .*{name}"):
        load_scene({"camera": CAM, "objects": [{"type": "mesh", "file": name}]},
                   base_dir=tmp_path)


def test_unknown_suffix_and_nan_vertices(tmp_path):
    with pytest.raises(PrefilterError, match=r"objects\[0\]\.file: expected a .obj/.ply"):
        scene({"type": "mesh", "file": str(tmp_path / "x.stl")})
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(PrefilterError, match=r"nan\.obj: expected finite vertex positions"):
        scene({"type": "mesh", "file": str(tmp_path / "nan.obj")})


def test_no_uvs_with_a_textured_material(tmp_path):
    """Without UVs a plain material renders; a normal map (or anisotropy) is refused."""
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    s = scene({"type": "mesh", "file": str(tmp_path / "t.obj")})
    t = s.objects[0].data.tangents
    assert abs(np.sum(t[:, :3] * s.objects[0].data.normals, 1)).max() < 1e-12
    with pytest.raises(PrefilterError, match=r"objects\[0\]\.file: .*t\.obj has no texture "
                                             r"coordinates \(UVs\), but the material's "
                                             r"normal_map needs them"):
        scene({"type": "mesh", "file": str(tmp_path / "t.obj"),
               "material": {"normal_map": {"procedural": "gaussian", "size": 16}}})
    with pytest.raises(PrefilterError, match="alpha_x needs them"):
        scene({"type": "mesh", "file": str(tmp_path / "t.obj"),
               "material": {"alpha_x": 0.1, "alpha_y": 0.4}})


@pytest.mark.parametrize("transform, match", [
    ([[1, 0, 0, 0]], r"transform: expected a 4 x 4 matrix"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]], r"transform\[3\]: expected "),
    ({"scale": 0}, r"transform: expected an invertible transform"),
    ({"shear": 1}, r"transform\.shear: unknown field"),
])
def test_bad_transforms(tmp_path, transform, match):
    p = write_quad(tmp_path / "q.obj")
    with pytest.raises(PrefilterError, match=match):
        scene({"type": "mesh", "file": str(p), "transform": transform})


def test_non_manifold_mesh_is_named(tmp_path):
    """Three triangles on one edge (a fin): one error naming the file and the edge."""
    (tmp_path / "fin.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\n"
                                      "f 1 2 3\nf 2 1 4\nf 1 2 5\n")
    with pytest.raises(PrefilterError, match=r"objects\[0\]\.file: .*fin\.obj: expected a "
                                             r"manifold mesh, got 1 edge\(s\) shared by more "
                                             r"than two triangles \(the first between "
                                             r"vertices 0 and 1\)"):
        scene({"type": "mesh", "file": str(tmp_path / "fin.obj")})
    from prefilter.render.mesh import non_manifold_edges

    assert non_manifold_edges(np.array([[0, 1, 2], [1, 0, 3]])).shape == (0, 2)


def test_huge_mesh_is_refused_before_reading(tmp_path, monkeypatch):
    """A PLY header of 10^9 triangles is refused from its header, naming the budget; with a
    small budget an ordinary file is refused from its size before trimesh reads it."""
    (tmp_path / "huge.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 500000000\nproperty float x\n"
        b"property float y\nproperty float z\nelement face 1000000000\n"
        b"property list uchar int vertex_indices\nend_header\n")
    with pytest.raises(PrefilterError, match=r"huge\.ply: a mesh of 1,000,000,000 triangles "
                                             r"\(its PLY header\): needs about .* more than "
                                             r"the memory budget"):
        scene({"type": "mesh", "file": str(tmp_path / "huge.ply")})
    p = write_quad(tmp_path / "q.obj")
    monkeypatch.setenv("PREFILTER_MEMORY_BUDGET", "64")
    with pytest.raises(PrefilterError, match=r"q\.obj: reading a mesh file of .* MiB: needs "
                                             r"about .* more than the memory budget"):
        scene({"type": "mesh", "file": str(p)})
