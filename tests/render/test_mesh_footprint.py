"""Ray-differential footprints on triangles: the analytic plane exactly, finite differences of
neighbouring primary rays, and the analytic sphere within the tessellation's error."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("embreex")

from mesh_assets import write_quad, write_uv_sphere  # noqa: E402

from prefilter.render import gbuffer, gbuffer_at, load_scene, pixel_positions  # noqa: E402

CAM = {"origin": [0.4, 1.5, 3], "target": [0, 0, 0], "fov": 40, "width": 96, "height": 64}
FIELDS = ("position", "normal", "tangent", "bitangent", "uv", "dudv", "dpdx", "dpdy",
          "distance", "view", "direction")


def scene(*objects, cam=CAM):
    return load_scene({"camera": cam, "objects": list(objects)})


def test_two_triangles_are_the_analytic_plane(tmp_path):
    """A 2-triangle quad gives the analytic plane's G-buffer to rounding (1e-12 world units /
    texture units): same hits, frame, uv and footprint."""
    quad = write_quad(tmp_path / "quad.obj", (4.0, 3.0))
    a = gbuffer(scene({"type": "plane", "size": [4, 3]}))
    b = gbuffer(scene({"type": "mesh", "file": str(quad)}))
    np.testing.assert_array_equal(a.hit, b.hit)
    assert a.hit.sum() > 1000
    for k in FIELDS:
        np.testing.assert_allclose(getattr(b, k)[a.hit], getattr(a, k)[a.hit], atol=1e-12,
                                   err_msg=k)


def test_mesh_beside_a_sphere_keeps_object_ids(tmp_path):
    """Meshes and analytic objects in one scene: nearest hit wins, ids index scene.objects."""
    quad = write_quad(tmp_path / "quad.ply")
    s = scene({"type": "sphere", "radius": 0.5, "center": [0, 0.5, 0]},
              {"type": "mesh", "file": str(quad)})
    g = gbuffer(s)
    only_plane = gbuffer(scene({"type": "mesh", "file": str(quad)}))
    only_sphere = gbuffer(scene({"type": "sphere", "radius": 0.5, "center": [0, 0.5, 0]}))
    np.testing.assert_array_equal(g.object_id[only_sphere.hit], 0)
    np.testing.assert_array_equal(g.object_id[only_plane.hit & ~only_sphere.hit], 1)
    np.testing.assert_array_equal(g.hit, only_plane.hit | only_sphere.hit)


def _finite_differences(s, h=1e-3):
    """Central differences of uv and position over +-h pixels in x and y at pixel centres."""
    xy = pixel_positions(s.camera)
    g = gbuffer_at(s, xy)
    ok = g.hit.copy()
    duv, dp = [], []
    for e in ([h, 0.0], [0.0, h]):
        gp, gm = gbuffer_at(s, xy + e), gbuffer_at(s, xy - e)
        ok &= gp.hit & gm.hit & (gp.object_id == g.object_id) & (gm.object_id == g.object_id)
        d = gp.uv - gm.uv
        ok &= np.all(np.abs(d) < 0.25, -1)  # not across the u seam
        duv.append(d / (2 * h))
        dp.append((gp.position - gm.position) / (2 * h))
    return g, ok, np.stack(duv, -1), dp


@pytest.mark.parametrize("asset", ["quad", "sphere"])
def test_footprint_matches_finite_differences(tmp_path, asset):
    """d uv / d pixel and d p / d pixel of the ray differentials equal central differences of
    neighbouring primary rays (h = 1e-3 pixel): to 1e-6 relative where both neighbours stay on
    the hit's triangle (uv is linear there); the few pixels whose neighbours cross an edge see
    the kink of the piecewise-linear uv, so 99 % of pixels are checked."""
    if asset == "quad":
        obj = {"type": "mesh", "file": str(write_quad(tmp_path / "q.glb"))}
    else:
        obj = {"type": "mesh", "file": str(write_uv_sphere(tmp_path / "s.obj", 16, 32))}
    g, ok, duv, (dpx, dpy) = _finite_differences(scene(obj))
    assert ok.sum() > 1000
    jac = g.dudv[ok]
    rel = np.linalg.norm(duv[ok] - jac, axis=(-2, -1)) / np.linalg.norm(jac, axis=(-2, -1))
    relp = (np.linalg.norm(dpx[ok] - g.dpdx[ok], axis=-1)
            + np.linalg.norm(dpy[ok] - g.dpdy[ok], axis=-1)) / (
        np.linalg.norm(g.dpdx[ok], axis=-1) + np.linalg.norm(g.dpdy[ok], axis=-1))
    assert np.quantile(rel, 0.99) < 1e-6
    assert np.quantile(relp, 0.99) < 1e-6


@pytest.mark.parametrize("n_theta", [32, 64])
def test_tessellated_sphere_approaches_the_analytic_sphere(tmp_path, n_theta):
    """A UV sphere of ``n_theta x 2 n_theta`` segments against the analytic sphere, with the
    ring spacing ``D = pi / n_theta``: positions (r = 1), normals, tangents and uv agree to
    O(D^2), the footprint ``dudv`` to O(D) (the facet's plane is tilted by up to D / 2 against
    the tangent plane). Checked where both hit, off the silhouette (``n . view > 0.3``) and the
    poles (``sin theta > 0.2``, where d u / d p of the analytic sphere diverges)."""
    sphere = write_uv_sphere(tmp_path / "s.ply", n_theta, 2 * n_theta)
    cam = dict(CAM, width=128, height=128, origin=[0.4, 0.8, 3])
    a = gbuffer(scene({"type": "sphere", "radius": 1.0}, cam=cam))
    b = gbuffer(scene({"type": "mesh", "file": str(sphere)}, cam=cam))
    assert np.mean(a.hit != b.hit) < 0.005  # silhouette pixels only
    m = (a.hit & b.hit & (np.sum(a.normal * a.view, -1) > 0.3)
         & (np.hypot(a.normal[..., 0], a.normal[..., 2]) > 0.2))
    d = np.pi / n_theta

    def angle(x, y):
        return np.arccos(np.clip(np.sum(x[m] * y[m], -1), -1.0, 1.0))

    assert np.linalg.norm(a.position[m] - b.position[m], axis=-1).max() < d**2
    assert angle(a.normal, b.normal).max() < d**2
    assert angle(a.tangent, b.tangent).max() < 1.5 * d**2
    assert angle(a.bitangent, b.bitangent).max() < 1.5 * d**2
    duv = np.abs(a.uv[m] - b.uv[m])
    duv[:, 0] = np.minimum(duv[:, 0], 1.0 - duv[:, 0])  # the seam
    assert duv.max() < 0.25 * d**2
    rel = (np.linalg.norm(a.dudv[m] - b.dudv[m], axis=(-2, -1))
           / np.linalg.norm(a.dudv[m], axis=(-2, -1)))
    assert rel.max() < 3 * d
    assert np.median(rel) < 0.3 * d
