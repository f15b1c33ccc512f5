"""Rays, footprints and sphere frames against closed forms and finite differences."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.render import gbuffer, gbuffer_at, generate_rays, load_scene, rays_at


def _scene(camera, objects):
    return load_scene({"camera": camera, "objects": objects})


def _cam(origin, target, up=(0, 1, 0), fov=40.0, w=64, h=48):
    return {"origin": list(origin), "target": list(target), "up": list(up), "fov": fov,
            "width": w, "height": h}


GROUND = {"type": "plane", "size": [1000, 1000], "uv_scale": [1000, 1000]}  # uv = world metres


def test_rays_centre_corner_and_differentials():
    s = _scene(_cam((1, 2, 3), (1, 2, 0), fov=60.0, w=40, h=30), [GROUND])
    r = rays_at(s.camera, np.array([[20.0, 15.0], [0.0, 0.0]]))
    assert np.allclose(r.direction[0], [0, 0, -1])
    t = np.tan(np.radians(30))
    assert np.allclose(r.direction[1], np.array([-t * 40 / 30, t, -1]) / np.sqrt(
        1 + t * t + (t * 4 / 3) ** 2))
    h = 1e-4
    xy = np.array([[7.3, 11.2]])
    fd = (rays_at(s.camera, xy + [h, 0]).direction
          - rays_at(s.camera, xy - [h, 0]).direction) / (2 * h)
    assert np.allclose(rays_at(s.camera, xy).ddx, fd, atol=1e-8)
    assert generate_rays(s.camera).direction.shape == (30, 40, 3)


@pytest.mark.parametrize("tilt_deg", [0.0, 30.0, 60.0])
def test_plane_footprint_matches_analytic_jacobian(tilt_deg):
    # camera at distance D from the image-centre hit point, tilted by theta from the normal,
    # looking down the -z direction of the ground: the centre pixel covers w = 2 D tan(fov/2) / H
    # across and w / cos(theta) along the tilt; uv = (x, -z) + const on this plane.
    D, fov, H, W = 5.0, 40.0, 48, 64
    th = np.radians(tilt_deg)
    origin = [0.0, D * np.cos(th), D * np.sin(th)]
    up = [0.0, 0.0, -1.0] if tilt_deg == 0 else [0.0, 1.0, 0.0]
    s = _scene(_cam(origin, (0, 0, 0), up=up, fov=fov, w=W, h=H), [GROUND])
    g = gbuffer_at(s, np.array([W / 2, H / 2]))
    w = 2 * D * np.tan(np.radians(fov) / 2) / H
    # pixel x -> world +x -> u; pixel y (down the image) -> towards the camera = +z -> v = -z
    expected = np.array([[w, 0.0], [0.0, -w / np.cos(th)]])
    assert g.hit and g.distance == pytest.approx(D)
    assert np.allclose(g.dudv, expected, rtol=1e-9, atol=1e-12)


def test_footprint_matches_finite_differences_everywhere():
    s = _scene(_cam((0.3, 2, 4), (0, 0, -3), fov=50), [
        {"type": "plane", "size": [40, 40], "uv_scale": [7, 3], "tangent": [1, 0, 0.5]},
        {"type": "sphere", "center": [1, 1, -2], "radius": 1.0, "uv_scale": [4, 2]}])
    xy = np.random.default_rng(0).uniform([0, 0], [64, 48], (400, 2))
    g = gbuffer_at(s, xy)
    h = 1e-4
    for axis in (0, 1):
        e = np.zeros(2)
        e[axis] = h
        gp, gm = gbuffer_at(s, xy + e), gbuffer_at(s, xy - e)
        ok = g.hit & (gp.object_id == g.object_id) & (gm.object_id == g.object_id)
        ok &= np.all(np.abs(gp.uv - gm.uv) < 0.1, -1)  # not across the sphere's seam
        fd = (gp.uv - gm.uv)[ok] / (2 * h)
        assert ok.sum() > 200
        assert np.allclose(g.dudv[ok][..., axis], fd, rtol=1e-5, atol=1e-7)
        dp = (gp.position - gm.position)[ok] / (2 * h)
        assert np.allclose((g.dpdx if axis == 0 else g.dpdy)[ok], dp, rtol=1e-5, atol=1e-7)


def test_sphere_frame_and_uv():
    c, r = np.array([0.5, 1.0, -2.0]), 0.7
    s = _scene(_cam((0, 1.5, 3), c), [{"type": "sphere", "center": c.tolist(), "radius": r,
                                       "uv_scale": [2, 3]}])
    g = gbuffer(s)
    m = g.hit
    assert m.sum() > 100 and np.all(g.object_id[m] == 0)
    q = g.position[m] - c
    assert np.allclose(np.linalg.norm(q, axis=-1), r)
    n, t, b = g.normal[m], g.tangent[m], g.bitangent[m]
    assert np.allclose(n, q / r)
    for a, bb in ((n, t), (n, b), (t, b)):
        assert np.allclose(np.sum(a * bb, -1), 0, atol=1e-12)
    assert np.allclose(np.cross(t, b), n)  # right-handed
    theta = np.arccos(q[:, 1] / r)  # pole +y, phi from +x towards +z
    phi = np.mod(np.arctan2(q[:, 2], q[:, 0]), 2 * np.pi)
    assert np.allclose(g.uv[m], np.stack([phi / (2 * np.pi) * 2, theta / np.pi * 3], -1))
    # tangent along increasing phi (latitude), bitangent along increasing theta
    dphi = np.stack([-np.sin(phi), 0 * phi, np.cos(phi)], -1)
    dth = np.stack([np.cos(theta) * np.cos(phi), -np.sin(theta), np.cos(theta) * np.sin(phi)], -1)
    assert np.allclose(t, dphi) and np.allclose(b, dth)
    # rays hit the front: the view is on the normal's side
    assert np.all(np.sum(g.view[m] * n, -1) > 0)


def test_subpixel_offsets_and_jitter():
    s = _scene(_cam((0, 1, 3), (0, 0, 0), w=8, h=6), [GROUND])
    offs = np.array([[-0.25, -0.25], [0.25, 0.1], [0.0, 0.4]])
    g = gbuffer(s, offsets=offs)
    assert g.shape == (6, 8, 3) and g.dudv.shape == (6, 8, 3, 2, 2)
    ys, xs = np.mgrid[0:6, 0:8] + 0.5
    xy = np.stack([xs, ys], -1)[:, :, None, :] + offs
    direct = gbuffer_at(s, xy)
    assert np.array_equal(g.uv, direct.uv)
    gj = gbuffer(s, jitter=(0.3, -0.2))
    assert np.allclose(gj.uv, gbuffer_at(s, np.stack([xs, ys], -1) + [0.3, -0.2]).uv)
    flat = g.reshape(-1)
    assert flat.position.shape == (144, 3) and flat.select(flat.hit).hit.all()
    with pytest.raises(PrefilterError, match="offsets"):
        gbuffer(s, offsets=np.zeros((5, 5, 2, 2)))


def test_misses_and_nearest_object():
    s = _scene(_cam((0, 0.5, 5), (0, 0.5, 0), w=32, h=32), [
        {"type": "sphere", "center": [0, 0.5, -1], "radius": 1.0},
        {"type": "sphere", "center": [0, 0.5, 1], "radius": 0.5}])
    g = gbuffer(s)
    assert g.object_id[16, 16] == 1 and g.distance[16, 16] == pytest.approx(3.5, abs=0.01)
    assert not g.hit[0, 0] and g.object_id[0, 0] == -1 and np.isinf(g.distance[0, 0])
    assert np.allclose(np.linalg.norm(g.view, axis=-1), 1.0)


def _assert_same_gbuffer(g, want):
    from dataclasses import fields

    for f in fields(g):
        a, b = getattr(g, f.name), getattr(want, f.name)
        assert a.shape == b.shape and a.dtype == b.dtype, f.name
        if a.dtype == bool or a.dtype.kind == "i":
            assert np.array_equal(a, b), f.name
        else:
            assert np.allclose(a, b, rtol=1e-9, atol=1e-9, equal_nan=False), f.name


def test_numba_gbuffer_matches_the_numpy_path_on_random_scenes():
    from gbuffer_numpy import intersect_numpy

    rng = np.random.default_rng(7)
    for trial in range(4):
        objects = [{"type": "plane", "center": rng.normal(size=3).tolist(),
                    "normal": rng.normal(size=3).tolist(), "tangent": rng.normal(size=3).tolist(),
                    "size": rng.uniform(6, 14, 2).tolist(),
                    "uv_scale": rng.uniform(1, 5, 2).tolist()},
                   {"type": "sphere", "center": (rng.normal(size=3) * [1, 1, 0.5]).tolist(),
                    "radius": float(rng.uniform(0.8, 1.8)), "pole": rng.normal(size=3).tolist(),
                    "axis_x": rng.normal(size=3).tolist(), "uv_scale": [3, 2]}]
        s = _scene(_cam(rng.normal(size=3) * 0.3 + [0, 0, 5], (0, 0, 0), fov=70.0, w=40, h=30),
                   objects)
        xy = rng.uniform([-5, -5], [45, 35], (500, 2))  # also off-image positions
        want = intersect_numpy(s, rays_at(s.camera, xy))
        assert want.hit.sum() > 40 and (~want.hit).sum() > 10
        _assert_same_gbuffer(gbuffer_at(s, xy), want)
        # and the kernel for given rays, with per-ray origins (not only the camera's)
        r = rays_at(s.camera, xy)
        shifted = type(r)(r.origin + rng.normal(size=(500, 3)) * 0.2, r.direction, r.ddx, r.ddy)
        from prefilter.render.camera import intersect

        _assert_same_gbuffer(intersect(s, shifted), intersect_numpy(s, shifted))


def test_gbuffer_does_not_depend_on_the_thread_count():
    import numba

    s = _scene(_cam((0.3, 2, 4), (0, 0, -3), fov=50), [
        {"type": "plane", "size": [40, 40], "uv_scale": [7, 3]},
        {"type": "sphere", "center": [1, 1, -2], "radius": 1.0}])
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = gbuffer(s)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        b = gbuffer(s)
    finally:
        numba.set_num_threads(before)
    assert a.position.tobytes() == b.position.tobytes() and a.dudv.tobytes() == b.dudv.tobytes()
