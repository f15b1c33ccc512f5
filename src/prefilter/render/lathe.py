"""Bodies of revolution as triangle meshes with UVs: the shipped path-tracing scenes' assets,
written by the project (nothing downloaded).

A profile ``(r_k, y_k)`` (radius and height, from the bottom pole to the top) is revolved about
the ``y`` axis: ``u`` runs around (``u_repeat`` times over the circumference, so a brushed normal
map along ``+u`` is brushed around the body, as on a lathe), ``v`` along the profile's arc length
(``v_repeat`` times). Normals are the profile's exact ones (the seam and the rings stay smooth).
:func:`prefilter.render.mitsuba_export.write_ply` writes them as PLY files.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError

__all__ = ["lathe", "smooth_profile"]


def smooth_profile(points, n: int = 48) -> np.ndarray:
    """``n`` points ``(n, 2)`` of the Catmull-Rom spline through ``points (K, 2)`` (``(r, y)``),
    uniform in the spline parameter."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 2:
        raise PrefilterError(f"points: expected (K >= 2, 2) profile points, got {p.shape}")
    q = np.concatenate([p[:1], p, p[-1:]])
    t = np.linspace(0.0, len(p) - 1.0, n)
    i = np.minimum(t.astype(int), len(p) - 2)
    s = (t - i)[:, None]
    p0, p1, p2, p3 = q[i], q[i + 1], q[i + 2], q[i + 3]
    return 0.5 * (2 * p1 + (p2 - p0) * s + (2 * p0 - 5 * p1 + 4 * p2 - p3) * s * s
                  + (3 * p1 - p0 - 3 * p2 + p3) * s ** 3)


def lathe(profile, segments: int = 64, u_repeat: float = 1.0, v_repeat: float = 1.0):
    """The mesh of ``profile (K, 2)`` revolved about ``y``: ``vertices (V, 3)``, ``faces (F, 3)``,
    ``normals (V, 3)``, ``uv (V, 2)`` (renderer texture space, ``v`` down the image).

    Faces are counter-clockwise seen from outside; ``u`` grows from ``+z`` towards ``-x`` and
    ``v`` from the top down, so the tangent frame is right-handed (``t x b`` outward). Rings of
    radius 0 (poles) keep one triangle per segment."""
    pr = np.asarray(profile, dtype=np.float64)
    k = len(pr)
    seg = int(segments)
    phi = np.linspace(0.0, 2.0 * np.pi, seg + 1)  # the seam repeated (u = 0 and u = 1)
    # arc length along the profile for v; tangent (dr, dy) by central differences
    ds = np.linalg.norm(np.diff(pr, axis=0), axis=-1)
    arc = np.concatenate([[0.0], np.cumsum(ds)]) / max(ds.sum(), 1e-300)
    tan = np.gradient(pr, axis=0)
    # outward normal of the profile curve in the (r, y) half-plane: (dy, -dr) rotated
    nr, ny = tan[:, 1], -tan[:, 0]
    ln = np.maximum(np.hypot(nr, ny), 1e-300)
    nr, ny = nr / ln, ny / ln
    c, s = np.cos(phi), np.sin(phi)
    # u grows from +z towards -x, v downwards: t = dp/du, b = dp/dv, t x b = the outward normal
    x = -pr[:, :1] * s[None]
    z = pr[:, :1] * c[None]
    y = np.broadcast_to(pr[:, 1:2], x.shape)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    normals = np.stack([-nr[:, None] * s[None], np.broadcast_to(ny[:, None], x.shape),
                        nr[:, None] * c[None]], -1).reshape(-1, 3)
    u = np.broadcast_to(phi[None] / (2 * np.pi) * u_repeat, x.shape)
    # v down the image from the top of the body
    v = np.broadcast_to((1.0 - arc)[:, None] * v_repeat, x.shape)
    uv = np.stack([u, v], -1).reshape(-1, 2)
    faces = []
    for i in range(k - 1):
        a = i * (seg + 1) + np.arange(seg)
        b = a + seg + 1
        if pr[i, 0] > 0:
            faces.append(np.stack([a, a + 1, b + 1], -1))
        if pr[i + 1, 0] > 0:
            faces.append(np.stack([a, b + 1, b], -1))
    f = np.concatenate(faces).astype(np.int64)
    # orient the faces outward (their geometric normal along the vertex normals)
    e = np.cross(verts[f[:, 1]] - verts[f[:, 0]], verts[f[:, 2]] - verts[f[:, 0]])
    flip = np.sum(e * normals[f].sum(1), -1) < 0
    f[flip] = f[flip][:, ::-1]
    return verts, f, normals, uv
