"""Lights for shading: one-sided quad area lights, point lights, directional lights.

Conventions (also in ``docs/reference.md``):

* A quad light is 4 coplanar corners ``v0..v3`` of a convex quad and a constant radiance (rgb).
  It is **one-sided**: it emits towards the side from which its corners are seen
  counter-clockwise, i.e. along the right-handed normal ``n = (v1 - v0) x (v2 - v0)``. This is the
  side where :func:`prefilter.ltc.polygon_integral` (front face = counter-clockwise seen from the
  shading point) is positive, so the LTC and Monte Carlo shaders agree on it.
* A point light has an intensity (rgb, W/sr): irradiance ``I cos / d^2``.
* A directional light has a direction of travel and an irradiance (rgb) on a surface facing it.

Sampling: uniform area sampling of the quad, converted to solid angle
(``pdf = d^2 / (A |cos_l|)``), and the matching density of a direction that hits the quad, so
light samples can be combined with BRDF samples by multiple importance sampling.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from prefilter.validation import as_float_array
from prefilter.errors import PrefilterError


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
