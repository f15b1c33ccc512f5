"""NumPy twin of the G-buffer kernels (:func:`prefilter.render.camera.intersect`): the check the
compiled ray casts are tested against."""

from __future__ import annotations

import numpy as np

from prefilter.render.camera import GBuffer, Rays

_EPS = 1e-9


def _hit_plane(obj, o, d):
    """Distance to a finite plane (``inf`` on a miss), frame and uv as functions of the point."""
    n, t_ax = obj.normal, obj.tangent
    denom = d @ n
    ok = np.abs(denom) > 1e-12
    t = np.where(ok, ((obj.center - o) @ n) / np.where(ok, denom, 1.0), np.inf)
    p = o + t[..., None] * d
    q = p - obj.center
    b_ax = np.cross(n, t_ax)
    a, b = q @ t_ax, q @ b_ax
    inside = ok & (t > _EPS) & (np.abs(a) <= obj.size[0] / 2) & (np.abs(b) <= obj.size[1] / 2)
    return np.where(inside, t, np.inf)


def _plane_geometry(obj, p):
    shape = p.shape[:-1]
    b_ax = np.cross(obj.normal, obj.tangent)
    q = p - obj.center
    su, sv = obj.uv_scale / obj.size
    uv = np.stack([(q @ obj.tangent) * su + 0.5 * obj.uv_scale[0],
                   (q @ b_ax) * sv + 0.5 * obj.uv_scale[1]], -1)
    duv_dp = np.broadcast_to(np.stack([obj.tangent * su, b_ax * sv]), shape + (2, 3))
    frame = [np.broadcast_to(v, shape + (3,)) for v in (obj.normal, obj.tangent, b_ax)]
    return frame, uv, duv_dp


def _hit_sphere(obj, o, d):
    oc = o - obj.center
    b = np.sum(oc * d, -1)
    c = np.sum(oc * oc, -1) - obj.radius**2
    disc = b * b - c
    ok = disc >= 0.0
    s = np.sqrt(np.where(ok, disc, 0.0))
    t0, t1 = -b - s, -b + s
    t = np.where(t0 > _EPS, t0, t1)
    return np.where(ok & (t > _EPS), t, np.inf)


def _sphere_geometry(obj, p):
    """Outward normal; tangent d p / d phi, bitangent d p / d theta, uv = (phi / 2pi, theta / pi)
    times uv_scale, in the sphere's local axes (``pole`` = theta 0, ``axis_x`` = phi 0)."""
    ex, ey = obj.axis_x, obj.pole
    ez = np.cross(ex, ey)
    q = (p - obj.center) / obj.radius
    x, y, z = q @ ex, np.clip(q @ ey, -1.0, 1.0), q @ ez
    theta = np.arccos(y)
    phi = np.mod(np.arctan2(z, x), 2.0 * np.pi)
    st = np.maximum(np.sqrt(x * x + z * z), 1e-12)  # sin(theta), kept off the poles
    # at the exact pole phi is undefined: take phi = 0 so the frame stays orthonormal
    pole = np.sqrt(x * x + z * z) < 1e-12
    cp, sp = np.where(pole, 1.0, x / st), np.where(pole, 0.0, z / st)
    n = q / np.linalg.norm(q, axis=-1, keepdims=True)
    tangent = -sp[..., None] * ex + cp[..., None] * ez
    bitangent = (y * cp)[..., None] * ex - st[..., None] * ey + (y * sp)[..., None] * ez
    su, sv = obj.uv_scale
    uv = np.stack([phi / (2 * np.pi) * su, theta / np.pi * sv], -1)
    # grad phi = tangent / (r sin theta), grad theta = bitangent / r
    duv_dp = np.stack([tangent * (su / (2 * np.pi * obj.radius * st))[..., None],
                       bitangent * (sv / (np.pi * obj.radius))], -2)
    return [n, tangent, bitangent], uv, duv_dp


_SHAPES = {"plane": (_hit_plane, _plane_geometry), "sphere": (_hit_sphere, _sphere_geometry)}


def intersect_numpy(scene, rays: Rays) -> GBuffer:
    """NumPy implementation of :func:`prefilter.render.camera.intersect`."""
    o, d = np.asarray(rays.origin, float), np.asarray(rays.direction, float)
    shape = d.shape[:-1]
    best = np.full(shape, np.inf)
    oid = np.full(shape, -1, dtype=np.int32)
    for k, obj in enumerate(scene.objects):  # a loop over objects, not pixels
        t = _SHAPES[obj.type][0](obj, o, d)
        closer = t < best
        best = np.where(closer, t, best)
        oid[closer] = k
    hit = oid >= 0
    def z3():
        return np.zeros(shape + (3,))  # fresh zero pages are cheaper than copies

    g = GBuffer(hit=hit, object_id=oid, position=z3(), normal=z3(), tangent=z3(),
                bitangent=z3(), uv=np.zeros(shape + (2,)), dudv=np.zeros(shape + (2, 2)),
                dpdx=z3(), dpdy=z3(), distance=best, view=-d, direction=d)
    for k, obj in enumerate(scene.objects):
        m = oid == k
        if not np.any(m):
            continue
        t = best[m]
        dm = d[m]
        p = o[m] + t[:, None] * dm
        (n, tan, bit), uv, duv_dp = _SHAPES[obj.type][1](obj, p)
        dn = np.sum(dm * n, -1, keepdims=True)
        dpdx = t[:, None] * (rays.ddx[m] - np.sum(rays.ddx[m] * n, -1, keepdims=True) / dn * dm)
        dpdy = t[:, None] * (rays.ddy[m] - np.sum(rays.ddy[m] * n, -1, keepdims=True) / dn * dm)
        g.position[m], g.normal[m], g.tangent[m], g.bitangent[m] = p, n, tan, bit
        g.uv[m] = uv
        g.dpdx[m], g.dpdy[m] = dpdx, dpdy
        g.dudv[m] = np.stack([np.einsum("...ij,...j->...i", duv_dp, dpdx),
                              np.einsum("...ij,...j->...i", duv_dp, dpdy)], -1)
    return g
