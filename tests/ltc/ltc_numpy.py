"""NumPy twins of the LTC kernels, the checks they are tested against: the polygon integral
(:func:`polygon_integral_numpy`) and the ``ltc`` shader (:func:`shade_ltc_numpy`, also the shader
for table-like stand-ins: any object with ``lookup(wo, alpha) -> (M, magnitude, fresnel)`` and
``alpha_min``)."""

from __future__ import annotations

import numpy as np

from prefilter.sphere.polygon import (_AREA_RTOL, _PLANE_RTOL, clamped_cosine_integral,
                                   clip_to_horizon, polygon_integral_minv)
from prefilter.ltc.shading import scaled_inverse, spec_scale
from prefilter.render.lights import LightSet
from prefilter.render.shading import local_view, quad_local, shade_delta_lights


def shade_ltc_numpy(position, frame_t, frame_b, frame_n, view, alpha, base_color, f0,
                    lights: LightSet, table) -> np.ndarray:
    """NumPy implementation of :func:`prefilter.ltc.shading.shade_ltc`."""
    position = np.asarray(position, dtype=np.float64)
    ts, bs, ns = (np.asarray(a, dtype=np.float64) for a in (frame_t, frame_b, frame_n))
    alpha = np.asarray(alpha, dtype=np.float64)
    base_color = np.asarray(base_color, dtype=np.float64)
    f0 = np.asarray(f0, dtype=np.float64)
    wo = local_view(view, ts, bs, ns)
    out = shade_delta_lights(position, ts, bs, ns, wo, alpha, alpha, base_color, f0, lights)
    if not lights.quads:
        return out
    # Roughness below the table's range uses its smoothest row (documented in docs/reference.md).
    M, magnitude, fresnel = table.lookup(wo, np.clip(alpha, table.alpha_min, 1.0))
    M_inv = scaled_inverse(M)
    spec = spec_scale(f0, magnitude, fresnel)
    for ql in lights.quads:
        P = quad_local(ql, position, ts, bs, ns)
        front = (position - ql.vertices[0]) @ ql.normal > 0.0
        e_d = clamped_cosine_integral(P)
        # The light is cut at the shading horizon before the LTC transform: the kernel clips
        # M^-1 P in the cosine's space, which would keep the lobe's mass below the surface.
        e_s = polygon_integral_minv(M_inv, clip_to_horizon(P))
        rad = base_color * e_d[:, None] + spec * e_s[:, None]
        out += np.where(front[:, None], rad, 0.0) * ql.radiance
    return out


def polygon_integral_numpy(M_inv, vertices, two_sided: bool = False) -> np.ndarray:
    """NumPy twin of :func:`prefilter.sphere.polygon.polygon_integral_minv`: explicit Sutherland-
    Hodgman (each input edge offers two output slots, valid or not), then the edge sum over
    consecutive valid slots. Same conventions as :func:`polygon_integral_minv`; no input
    validation. Component arrays ``(B, n)`` rather than ``np.cross`` on ``(..., 3)``, which is
    several times slower."""
    M_inv = np.asarray(M_inv, np.float64)
    V = np.asarray(vertices, np.float64)
    n = V.shape[-2]
    batch = np.broadcast_shapes(M_inv.shape[:-2], V.shape[:-2])
    Mb = np.broadcast_to(M_inv, batch + (3, 3)).reshape(-1, 3, 3)
    Vb = np.broadcast_to(V, batch + (n, 3)).reshape(-1, n, 3)
    Mb = Mb / np.abs(Mb).max(axis=(1, 2))[:, None, None]
    Lx, Ly, Lz = (Mb[:, r, 0:1] * Vb[..., 0] + Mb[:, r, 1:2] * Vb[..., 1]
                  + Mb[:, r, 2:3] * Vb[..., 2] for r in range(3))

    # edge-on / zero-area test (Newell normal, centroid, size)
    Px, Py, Pz = (np.roll(c, 1, axis=1) for c in (Lx, Ly, Lz))
    Nx = (Py * Lz - Pz * Ly).sum(1)
    Ny = (Pz * Lx - Px * Lz).sum(1)
    Nz = (Px * Ly - Py * Lx).sum(1)
    size = np.maximum(np.abs(Lx).max(1), np.maximum(np.abs(Ly).max(1), np.abs(Lz).max(1)))
    nn = np.sqrt(Nx * Nx + Ny * Ny + Nz * Nz)
    plane = np.abs(Nx * Lx.sum(1) + Ny * Ly.sum(1) + Nz * Lz.sum(1))
    edge_on = (nn <= _AREA_RTOL * n * size**2) | (plane <= _PLANE_RTOL * n * nn * size)

    # Sutherland-Hodgman: edge P->L emits the crossing point (slot 2i) if it crosses z = 0,
    # then L itself (slot 2i + 1) if L is inside
    p_in, l_in = Pz >= 0, Lz >= 0
    crossing = p_in != l_in
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crossing, Pz / (Pz - Lz), 0.0)
    Cx = np.stack([Px + t * (Lx - Px), Lx], axis=-1).reshape(-1, 2 * n)
    Cy = np.stack([Py + t * (Ly - Py), Ly], axis=-1).reshape(-1, 2 * n)
    Cz = np.stack([np.zeros_like(Lz), Lz], axis=-1).reshape(-1, 2 * n)
    valid = np.stack([crossing, l_in], axis=-1).reshape(-1, 2 * n)

    # edges join each valid slot to the next valid one (cyclically): scan the slots backwards,
    # carrying the coordinates of the next valid slot, which starts as the first valid slot
    first = np.argmax(valid, axis=1)[:, None]
    bx, by, bz = (np.take_along_axis(c, first, axis=1)[:, 0] for c in (Cx, Cy, Cz))
    total = np.zeros(Cx.shape[0])
    for j in range(2 * n - 1, -1, -1):
        ax, ay, az, ok = Cx[:, j], Cy[:, j], Cz[:, j], valid[:, j]
        cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        s = np.sqrt(cx * cx + cy * cy + cz * cz)
        theta = np.arctan2(s, ax * bx + ay * by + az * bz)
        with np.errstate(divide="ignore", invalid="ignore"):
            total += np.where(ok & (s > 0), theta * cz / s, 0.0)
        bx, by, bz = np.where(ok, ax, bx), np.where(ok, ay, by), np.where(ok, az, bz)
    e = -np.sign(np.linalg.det(Mb)) * total / (2 * np.pi)
    e = np.where(edge_on, 0.0, e)
    e = np.abs(e) if two_sided else np.maximum(0.0, e)
    return e.reshape(batch)
