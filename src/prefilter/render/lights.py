"""Lights for shading: one-sided quad area lights, point lights, directional lights.

Conventions (also in ``docs/reference.md``):

* A quad light is 4 coplanar corners ``v0..v3`` of a convex quad and a constant radiance (rgb).
  It is **one-sided**: it emits towards the side from which its corners are seen
  counter-clockwise, i.e. along the right-handed normal ``n = (v1 - v0) x (v2 - v0)``. This is the
  side where :func:`prefilter.sphere.polygon.polygon_integral` (front face = counter-clockwise
  seen from the shading point) is positive, so the LTC and Monte Carlo shaders agree on it.
* A point light has an intensity (rgb, W/sr): irradiance ``I cos / d^2``.
* A directional light has a direction of travel and an irradiance (rgb) on a surface facing it.

Sampling: uniform area sampling of the quad, converted to solid angle
(``pdf = d^2 / (A |cos_l|)``), and the matching density of a direction that hits the quad, so
light samples can be combined with BRDF samples by multiple importance sampling
(:func:`quad_light_sample`, :func:`quad_light_pdf`). Rectangles are also sampled uniformly in the
solid angle they subtend (Urena et al. 2013, "An area-preserving parametrization for spherical
rectangles"; ``pdf = 1 / Omega``): :func:`light_sample` and :func:`light_pdf` choose that
wherever the solid angle lies in ``[SOLID_ANGLE_MIN, SOLID_ANGLE_MAX]`` and area sampling
elsewhere (other quads, and rectangles seen at tiny or near-hemispherical solid angles, where
Urena's angles lose precision), the same rule for the sampler and its density.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.jit import kernel_array, njit_inline, njit_parallel, prange, serial
from prefilter.validation import as_float_array

#: Solid angles (sr) outside which a rectangle is sampled by area (the bounds of pbrt-v4's
#: spherical sampling, ``MinSphericalSampleArea`` and ``MaxSphericalSampleArea``).
SOLID_ANGLE_MIN, SOLID_ANGLE_MAX = 3e-4, 6.22

#: Columns of :func:`quad_rectangle`: corner ``v0`` (3), unit edges ``x = (v1 - v0) / |.|`` and
#: ``y = (v3 - v0) / |.|`` (3 each), the emission normal ``z = x cross y`` (3), the edge lengths.
RECT_WIDTH = 14


@dataclass(frozen=True)
class QuadLight:
    """A one-sided planar convex quad light: corners ``(4, 3)``, radiance ``(3,)``."""

    vertices: np.ndarray
    radiance: np.ndarray

    def __post_init__(self):
        v = as_float_array(self.vertices, "quad light vertices")
        if v.shape != (4, 3):
            raise PrefilterError(f"quad light vertices: expected shape (4, 3), got {v.shape}")
        r = _rgb(self.radiance, "quad light radiance")
        normal, area = quad_normal_area(v)
        # relative to the quad's own size, so that scenes in any unit behave alike
        size = float(np.max(np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=-1)))
        if not area > 1e-12 * size * size:
            raise PrefilterError(f"quad light vertices: expected a convex quad with area > 0, "
                                 f"got {v.tolist()}")
        # Coplanarity: every corner within a small distance of the plane through the centroid.
        off = np.abs((v - v.mean(0)) @ normal)
        if np.max(off) > 1e-6 * size:
            raise PrefilterError(
                f"quad light vertices: expected 4 coplanar corners, got one {np.max(off):.3g} "
                "off the plane"
            )
        e = np.roll(v, -1, axis=0) - v
        turn = np.cross(e, np.roll(e, -1, axis=0)) @ normal
        if np.any(turn < -1e-12 * area):
            raise PrefilterError("quad light vertices: expected a convex quad in corner order")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "radiance", r)

    @property
    def normal(self) -> np.ndarray:
        """Unit emission normal ``(3,)``."""
        return quad_normal_area(self.vertices)[0]

    @property
    def area(self) -> float:
        return float(quad_normal_area(self.vertices)[1])


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light: position ``(3,)``, intensity ``(3,)`` (W/sr)."""

    position: np.ndarray
    intensity: np.ndarray

    def __post_init__(self):
        p = as_float_array(self.position, "point light position")
        if p.shape != (3,):
            raise PrefilterError(f"point light position: expected shape (3,), got {p.shape}")
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "intensity", _rgb(self.intensity, "point light intensity"))


@dataclass(frozen=True)
class DirectionalLight:
    """A distant light: unit ``direction (3,)`` of travel, ``irradiance (3,)``."""

    direction: np.ndarray
    irradiance: np.ndarray

    def __post_init__(self):
        d = as_float_array(self.direction, "directional light direction")
        if d.shape != (3,) or np.linalg.norm(d) < 1e-12:
            raise PrefilterError(
                f"directional light direction: expected a non-zero (3,) vector, got {d}"
            )
        object.__setattr__(self, "direction", d / np.linalg.norm(d))
        object.__setattr__(self, "irradiance", _rgb(self.irradiance, "directional irradiance"))


@dataclass(frozen=True)
class LightSet:
    """All lights of a scene, grouped by kind."""

    quads: tuple[QuadLight, ...] = field(default_factory=tuple)
    points: tuple[PointLight, ...] = field(default_factory=tuple)
    directionals: tuple[DirectionalLight, ...] = field(default_factory=tuple)

    def __len__(self) -> int:
        return len(self.quads) + len(self.points) + len(self.directionals)


def _rgb(x, name: str) -> np.ndarray:
    a = as_float_array(x, name)
    if a.ndim == 0:
        a = np.full(3, float(a))
    if a.shape != (3,) or np.any(a < 0):
        raise PrefilterError(f"{name}: expected a number or rgb triple >= 0, got {a}")
    return a


def quad_normal_area(vertices) -> tuple[np.ndarray, np.ndarray]:
    """Unit right-handed normal ``(..., 3)`` and area ``(...)`` of planar quads ``(..., 4, 3)``.

    The area vector of a planar quad is half the cross product of its diagonals.
    """
    v = np.asarray(vertices, dtype=np.float64)
    a = 0.5 * np.cross(v[..., 2, :] - v[..., 0, :], v[..., 3, :] - v[..., 1, :])
    area = np.linalg.norm(a, axis=-1)
    return a / np.maximum(area, 1e-300)[..., None], area


def sample_quad_area(vertices, u) -> np.ndarray:
    """Uniform points ``(N, 3)`` on a convex quad ``(4, 3)`` from uniforms ``u (N, 2)``.

    The quad is split into triangles (v0, v1, v2) and (v0, v2, v3), chosen in proportion to their
    areas by ``u_0`` (rescaled and reused), then sampled with the square-root warp
    (pbrt-v4, "Sampling a triangle").
    """
    v = np.asarray(vertices, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    a1 = 0.5 * np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0]))
    a2 = 0.5 * np.linalg.norm(np.cross(v[2] - v[0], v[3] - v[0]))
    p1 = a1 / (a1 + a2)
    first = u[:, 0] < p1
    u0 = np.where(first, u[:, 0] / p1, (u[:, 0] - p1) / (1.0 - p1 if p1 < 1 else 1.0))
    u0 = np.clip(u0, 0.0, 1.0)
    su = np.sqrt(u0)
    b0 = 1.0 - su
    b1 = u[:, 1] * su
    b = np.where(first[:, None], v[1], v[2])
    c = np.where(first[:, None], v[2], v[3])
    return v[0] + b1[:, None] * (c - v[0]) + (1.0 - b0 - b1)[:, None] * (b - v[0])


def quad_light_sample(light: QuadLight, position, u):
    """Sample a direction towards ``light`` from ``position (N, 3)`` with uniforms ``u (N, 2)``.

    Returns ``(wi (N, 3), pdf (N,))``: unit world directions and their solid-angle density
    ``d^2 / (A cos_l)``; ``pdf = 0`` where the sampled point is seen from the back side (no
    emission) or the distance vanishes.
    """
    y = sample_quad_area(light.vertices, u)
    d = y - position
    dist2 = np.sum(d * d, axis=-1)
    dist = np.sqrt(dist2)
    ok = dist > 1e-12
    wi = d / np.where(ok, dist, 1.0)[:, None]
    cos_l = -(wi @ light.normal)
    front = ok & (cos_l > 1e-12)
    pdf = np.where(front, dist2 / (light.area * np.where(front, cos_l, 1.0)), 0.0)
    return wi, pdf


def quad_light_pdf(light: QuadLight, position, wi) -> np.ndarray:
    """Solid-angle density ``(N,)`` of :func:`quad_light_sample` for directions ``wi (N, 3)``.

    Zero unless the ray ``position + t wi`` (t > 0) hits the front face of the quad.
    """
    n = light.normal
    v = light.vertices
    cos_l = -(wi @ n)
    front = cos_l > 1e-12
    t = ((v[0] - position) @ n) / np.where(front, -cos_l, -1.0)
    hit = front & (t > 0.0)
    x = position + t[:, None] * wi
    # Convex quad with corners counter-clockwise about n: inside iff left of every edge.
    for k in range(4):
        e = v[(k + 1) % 4] - v[k]
        hit &= (np.cross(e, x - v[k]) @ n) >= 0.0
    t = np.where(hit, t, 0.0)
    return np.where(hit, t * t / (light.area * np.where(hit, cos_l, 1.0)), 0.0)


# -------------------------------------------------- solid-angle sampling of rectangles (Urena)


def quad_rectangle(vertices) -> np.ndarray | None:
    """The rectangle frame ``(RECT_WIDTH,)`` of a quad ``(4, 3)`` whose corners form a rectangle
    (``v2 = v1 + v3 - v0`` and orthogonal edges, to 1e-9 relative), ``None`` otherwise."""
    v = np.asarray(vertices, dtype=np.float64)
    ex, ey = v[1] - v[0], v[3] - v[0]
    lx, ly = float(np.linalg.norm(ex)), float(np.linalg.norm(ey))
    if lx <= 0.0 or ly <= 0.0:
        return None
    size = max(lx, ly)
    if (np.linalg.norm(v[2] - v[1] - ey) > 1e-9 * size
            or abs(float(ex @ ey)) > 1e-9 * lx * ly):
        return None
    x, y = ex / lx, ey / ly
    return np.concatenate([v[0], x, y, np.cross(x, y), [lx, ly]])


@njit_inline
def spherical_rectangle_jit(ox, oy, oz, rect):
    """Urena et al. 2013, algorithm 1 (``SphQuadInit``): the spherical rectangle that the
    rectangle ``rect`` (:func:`quad_rectangle`) subtends at ``(ox, oy, oz)``.

    Returns ``(x0, x1, y0, y1, z0, b0, b1, k, omega)``: the rectangle's extent in the frame
    ``(x, y, z)`` centred at the point, the ``z`` of the normals of two of its edge planes,
    ``k = 2 pi - gamma_2 - gamma_3`` and the solid angle ``omega`` (0 when the point is not in
    front of the emitting side, ``z0 >= 0``).
    """
    dx, dy, dz = rect[0] - ox, rect[1] - oy, rect[2] - oz
    x0 = dx * rect[3] + dy * rect[4] + dz * rect[5]
    y0 = dx * rect[6] + dy * rect[7] + dz * rect[8]
    z0 = dx * rect[9] + dy * rect[10] + dz * rect[11]
    x1, y1 = x0 + rect[12], y0 + rect[13]
    if not z0 < 0.0:
        return x0, x1, y0, y1, z0, 0.0, 0.0, 0.0, 0.0
    z2 = z0 * z0
    # the unit normals of the planes through the point and each edge: n0 = (0, z0, -y0),
    # n1 = (-z0, 0, x1), n2 = (0, -z0, y1), n3 = (z0, 0, -x0), each over its length
    l0 = 1.0 / np.sqrt(z2 + y0 * y0)
    l1 = 1.0 / np.sqrt(z2 + x1 * x1)
    l2 = 1.0 / np.sqrt(z2 + y1 * y1)
    l3 = 1.0 / np.sqrt(z2 + x0 * x0)
    # interior angles gamma_i = acos(-n_i . n_i+1)
    g0 = np.arccos(min(max(y0 * x1 * l0 * l1, -1.0), 1.0))
    g1 = np.arccos(min(max(-x1 * y1 * l1 * l2, -1.0), 1.0))
    g2 = np.arccos(min(max(x0 * y1 * l2 * l3, -1.0), 1.0))
    g3 = np.arccos(min(max(-x0 * y0 * l3 * l0, -1.0), 1.0))
    k = 2.0 * np.pi - g2 - g3
    return x0, x1, y0, y1, z0, -y0 * l0, y1 * l2, k, g0 + g1 - k


@njit_inline
def spherical_rectangle_point_jit(x0, x1, y0, y1, z0, b0, b1, k, omega, u, v):
    """Urena et al. 2013, algorithm 1 (``SphQuadSample``): the point ``(xu, yv)`` of the
    rectangle's plane (frame of :func:`spherical_rectangle_jit`, ``z = z0``) whose direction is
    uniform in the spherical rectangle for uniforms ``(u, v)``."""
    au = u * omega + k
    fu = (np.cos(au) * b0 - b1) / np.sin(au)
    # cu = sign(fu) / sqrt(fu^2 + b0^2) and xu = -cu z0 / sqrt(1 - cu^2), with one root
    q = fu * fu + b0 * b0 - 1.0
    if q > 0.0:
        xu = -z0 / np.sqrt(q)
        if not fu > 0.0:
            xu = -xu
    else:  # |cu| clamped to 1: the edge the sign points to
        xu = x1 if fu > 0.0 else x0
    xu = min(max(xu, x0), x1)
    d2 = xu * xu + z0 * z0
    h0 = y0 / np.sqrt(d2 + y0 * y0)
    h1 = y1 / np.sqrt(d2 + y1 * y1)
    hv = h0 + v * (h1 - h0)
    hv2 = hv * hv
    yv = hv * np.sqrt(d2 / (1.0 - hv2)) if hv2 < 1.0 - 1e-12 else y1
    return xu, min(max(yv, y0), y1)


@njit_inline
def quad_setup_jit(ox, oy, oz, rect, is_rect):
    """The per-point state of :func:`quad_sample_jit` and :func:`quad_pdf_jit`: the tuple of
    :func:`spherical_rectangle_jit` where ``is_rect`` and the solid angle lies in
    ``[SOLID_ANGLE_MIN, SOLID_ANGLE_MAX]`` (solid-angle sampling), else with ``omega = -1``
    (area sampling)."""
    if is_rect:
        sr = spherical_rectangle_jit(ox, oy, oz, rect)
        if sr[8] == 0.0 or SOLID_ANGLE_MIN <= sr[8] <= SOLID_ANGLE_MAX:
            return sr
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0


@njit_inline
def quad_sample_jit(ox, oy, oz, verts, normal, area, p1, rect, sr, u0, u1):
    """A light sample of the quad ``verts (4, 3)`` (``normal``, ``area``, :func:`quad_constants`'
    ``p1``, ``rect`` of :func:`quad_rectangle`) seen from ``(ox, oy, oz)`` with the state ``sr``
    of :func:`quad_setup_jit`: uniform in solid angle (``sr[8] >= 0``) or on the area.

    Returns ``(wx, wy, wz, pdf, lx, ly, lz)``: the unit world direction, its solid-angle density
    (0 where the point does not see the emitting side) and the point on the light.
    """
    if sr[8] >= 0.0:
        if sr[8] == 0.0:
            return 0.0, 0.0, 1.0, 0.0, ox, oy, oz
        xu, yv = spherical_rectangle_point_jit(sr[0], sr[1], sr[2], sr[3], sr[4], sr[5], sr[6],
                                               sr[7], sr[8], u0, u1)
        z0 = sr[4]
        dx = xu * rect[3] + yv * rect[6] + z0 * rect[9]
        dy = xu * rect[4] + yv * rect[7] + z0 * rect[10]
        dz = xu * rect[5] + yv * rect[8] + z0 * rect[11]
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        return dx / dist, dy / dist, dz / dist, 1.0 / sr[8], ox + dx, oy + dy, oz + dz
    # uniform on the area (sample_quad_area): triangle (v0, v1, v2) or (v0, v2, v3)
    if u0 < p1:
        u0 = u0 / p1
        b_i, c_i = 1, 2
    else:
        u0 = (u0 - p1) / (1.0 - p1) if p1 < 1.0 else 0.0
        b_i, c_i = 2, 3
    u0 = min(max(u0, 0.0), 1.0)
    su = np.sqrt(u0)
    b1 = u1 * su
    b2 = su - b1
    lx = verts[0, 0] + b1 * (verts[c_i, 0] - verts[0, 0]) + b2 * (verts[b_i, 0] - verts[0, 0])
    ly = verts[0, 1] + b1 * (verts[c_i, 1] - verts[0, 1]) + b2 * (verts[b_i, 1] - verts[0, 1])
    lz = verts[0, 2] + b1 * (verts[c_i, 2] - verts[0, 2]) + b2 * (verts[b_i, 2] - verts[0, 2])
    dx, dy, dz = lx - ox, ly - oy, lz - oz
    dist2 = dx * dx + dy * dy + dz * dz
    dist = np.sqrt(dist2)
    if not dist > 1e-12:
        return 0.0, 0.0, 1.0, 0.0, lx, ly, lz
    dx, dy, dz = dx / dist, dy / dist, dz / dist
    cos_l = -(dx * normal[0] + dy * normal[1] + dz * normal[2])
    pdf = dist2 / (area * cos_l) if cos_l > 1e-12 else 0.0
    return dx, dy, dz, pdf, lx, ly, lz


@njit_inline
def quad_pdf_jit(ox, oy, oz, wx, wy, wz, verts, normal, area, d_plane, sr):
    """The density of :func:`quad_sample_jit` at the unit world direction ``(wx, wy, wz)`` from
    ``(ox, oy, oz)`` (``d_plane``: :func:`quad_constants`) and the ray's hit on the light:
    ``(pdf, hx, hy, hz)``, ``pdf = 0`` (and the hit the point itself) where the ray misses the
    front of the quad."""
    cos_l = -(wx * normal[0] + wy * normal[1] + wz * normal[2])
    if not cos_l > 1e-12:
        return 0.0, ox, oy, oz
    t = (d_plane - (ox * normal[0] + oy * normal[1] + oz * normal[2])) / (-cos_l)
    if not t > 0.0:
        return 0.0, ox, oy, oz
    hx, hy, hz = ox + t * wx, oy + t * wy, oz + t * wz
    # convex quad with corners counter-clockwise about the normal: inside iff left of every edge
    for k in range(4):
        k1 = (k + 1) % 4
        ex = verts[k1, 0] - verts[k, 0]
        ey = verts[k1, 1] - verts[k, 1]
        ez = verts[k1, 2] - verts[k, 2]
        qx, qy, qz = hx - verts[k, 0], hy - verts[k, 1], hz - verts[k, 2]
        if ((ey * qz - ez * qy) * normal[0] + (ez * qx - ex * qz) * normal[1]
                + (ex * qy - ey * qx) * normal[2]) < 0.0:
            return 0.0, ox, oy, oz
    if sr[8] >= 0.0:
        return (1.0 / sr[8] if sr[8] > 0.0 else 0.0), hx, hy, hz
    return t * t / (area * cos_l), hx, hy, hz


@njit_inline
def quad_constants(verts, normal, area):
    """``(p1, d)`` of a quad light ``verts (4, 3)``: the probability of its first triangle
    ``(v0, v1, v2)`` in :func:`sample_quad_area` and its plane's offset ``normal . v0``."""
    tri1 = 0.5 * np.sqrt(
        ((verts[1, 1] - verts[0, 1]) * (verts[2, 2] - verts[0, 2])
         - (verts[1, 2] - verts[0, 2]) * (verts[2, 1] - verts[0, 1])) ** 2
        + ((verts[1, 2] - verts[0, 2]) * (verts[2, 0] - verts[0, 0])
           - (verts[1, 0] - verts[0, 0]) * (verts[2, 2] - verts[0, 2])) ** 2
        + ((verts[1, 0] - verts[0, 0]) * (verts[2, 1] - verts[0, 1])
           - (verts[1, 1] - verts[0, 1]) * (verts[2, 0] - verts[0, 0])) ** 2)
    return tri1 / area, verts[0, 0] * normal[0] + verts[0, 1] * normal[1] + verts[0, 2] * normal[2]


def quad_arrays(light):
    """``(verts (4, 3), normal (3,), area, rect (RECT_WIDTH,), is_rect)`` of a quad light for the
    kernels (``rect`` zeros when the quad is not a rectangle)."""
    rect = quad_rectangle(light.vertices)
    return (np.ascontiguousarray(light.vertices, dtype=np.float64),
            np.ascontiguousarray(light.normal, dtype=np.float64), float(light.area),
            np.zeros(RECT_WIDTH) if rect is None else rect, rect is not None)


@njit_parallel
def light_sample_kernel(pos, u, verts, normal, area, rect, is_rect, wi, pdf, pts):
    """:func:`light_sample` over ``pos (N, 3)``, ``u (N, 2)``."""
    p1 = quad_constants(verts, normal, area)[0]
    for i in prange(pos.shape[0]):
        sr = quad_setup_jit(pos[i, 0], pos[i, 1], pos[i, 2], rect, is_rect)
        r = quad_sample_jit(pos[i, 0], pos[i, 1], pos[i, 2], verts, normal, area, p1, rect, sr,
                            u[i, 0], u[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2], pdf[i] = r[0], r[1], r[2], r[3]
        pts[i, 0], pts[i, 1], pts[i, 2] = r[4], r[5], r[6]


@njit_parallel
def light_pdf_kernel(pos, w, verts, normal, area, rect, is_rect, pdf, pts):
    """:func:`light_pdf` over ``pos, w (N, 3)``."""
    d_plane = quad_constants(verts, normal, area)[1]
    for i in prange(pos.shape[0]):
        sr = quad_setup_jit(pos[i, 0], pos[i, 1], pos[i, 2], rect, is_rect)
        r = quad_pdf_jit(pos[i, 0], pos[i, 1], pos[i, 2], w[i, 0], w[i, 1], w[i, 2], verts,
                         normal, area, d_plane, sr)
        pdf[i] = r[0]
        pts[i, 0], pts[i, 1], pts[i, 2] = r[1], r[2], r[3]


def light_sample(light: QuadLight, position, u):
    """A direction towards ``light`` from each of ``position (N, 3)``, uniforms ``u (N, 2)``:
    uniform in solid angle for rectangles (Urena et al. 2013), else on the area (see the
    module docstring for the rule).

    Returns ``(wi (N, 3), pdf (N,), points (N, 3))``: unit world directions, their solid-angle
    density (0 where the point does not see the emitting side) and the points on the light.
    """
    u = np.asarray(u, dtype=np.float64)
    pos = kernel_array(position, (len(u), 3), np.float64)
    u = kernel_array(u, u.shape)
    n = len(u)
    wi, pdf, pts = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    serial(light_sample_kernel, n)(pos, u, *quad_arrays(light), wi, pdf, pts)
    return wi, pdf, pts


def light_pdf(light: QuadLight, position, wi):
    """Solid-angle density ``(N,)`` of :func:`light_sample` at unit world directions
    ``wi (N, 3)``, and the rays' hits on the light ``(N, 3)`` (the point itself on a miss)."""
    w = np.asarray(wi, dtype=np.float64)
    w = kernel_array(w, w.shape)
    pos = kernel_array(position, w.shape, np.float64)
    n = len(w)
    pdf, pts = np.empty(n), np.empty((n, 3))
    serial(light_pdf_kernel, n)(pos, w, *quad_arrays(light), pdf, pts)
    return pdf, pts


def solid_angle(light: QuadLight, position) -> np.ndarray:
    """Solid angle ``(N,)`` a rectangular light subtends at ``position (N, 3)`` from its emitting
    side (Urena et al. 2013, the spherical rectangle's area), 0 behind it."""
    rect = quad_rectangle(light.vertices)
    if rect is None:
        raise PrefilterError("light: expected a rectangular quad light")
    pos = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    return np.array([spherical_rectangle_jit(p[0], p[1], p[2], rect)[8] for p in pos])
