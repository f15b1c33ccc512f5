"""Pinhole camera, ray differentials, ray-object intersection and the G-buffer.

Image conventions: pixel ``(row i, column j)`` covers ``x in [j, j+1)``, ``y in [i, i+1)`` with its
centre at ``(j + 0.5, i + 0.5)``; row 0 is the top of the image. Sample positions are given in
these continuous pixel coordinates ``(x, y)``.

World conventions: right-handed, y up; the camera looks from ``origin`` to ``target``;
``fov`` is the vertical field of view in degrees.

Footprints (Igehy 1999, "Tracing ray differentials"; pbrt-v4 section 10.1): for a hit point ``p``
on a surface with normal ``n`` reached by the direction ``d(x, y)``, the hit point moves on the
tangent plane as ``dp/dx = t (dd/dx - (n . dd/dx) / (n . d) d)`` (same for y), which is the exact
first derivative on planes and spheres alike (the tangent plane has first-order contact); the UV
Jacobian is ``d(uv)/d(pixel) = (d uv / d p) (dp/dx, dp/dy)``.

:func:`gbuffer`, :func:`gbuffer_at` and :func:`intersect` run one Numba pass per sample
(:mod:`prefilter.render.kernels`: ray, nearest hit, frame, uv and footprint, no masked gathers);
their NumPy twin is a check in ``tests/render/gbuffer_numpy.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from prefilter.jit import kernel_array
from prefilter.validation import as_float_array
from prefilter.errors import PrefilterError

__all__ = ["Camera", "GBuffer", "Rays", "gbuffer", "gbuffer_at", "generate_rays", "intersect",
           "pixel_positions", "rays_at"]


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Attributes
    ----------
    origin, target, up : numpy.ndarray, shape (3,)
        Eye position, a point it looks at and an approximate up vector (world units).
    fov : float
        Vertical field of view in degrees, in (0, 180).
    width, height : int
        Image size in pixels.
    """

    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: float
    width: int
    height: int

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit ``(right, true_up, forward)`` vectors, right-handed with ``forward = -back``."""
        f = self.target - self.origin
        f = f / np.linalg.norm(f)
        r = np.cross(f, self.up)
        r = r / np.linalg.norm(r)
        return r, np.cross(r, f), f

    def with_size(self, width: int, height: int) -> "Camera":
        return Camera(self.origin, self.target, self.up, self.fov, int(width), int(height))


@dataclass(frozen=True)
class Rays:
    """Primary rays: ``origin``, unit ``direction`` and their pixel derivatives ``ddx``, ``ddy``
    (derivatives of the unit direction w.r.t. pixel x and y), all ``(..., 3)``."""

    origin: np.ndarray
    direction: np.ndarray
    ddx: np.ndarray
    ddy: np.ndarray


@dataclass
class GBuffer:
    """Per-sample surface data, every array with leading shape ``(...)`` (e.g. ``(H, W)`` or
    ``(H, W, S)``).

    Attributes
    ----------
    hit : bool (...)
    object_id : int32 (...), index into ``scene.objects``, -1 where nothing is hit.
    position : (..., 3) world hit point.
    normal, tangent, bitangent : (..., 3) geometric frame; tangent = d p / d u direction,
        right-handed ``tangent x bitangent = normal``.
    uv : (..., 2) texture coordinates (scaled by the object's ``uv_scale``, not wrapped).
    dudv : (..., 2, 2) ``dudv[..., a, b] = d uv_a / d pixel_b`` (pixel axes x, y).
    dpdx, dpdy : (..., 3) derivatives of the hit point w.r.t. pixel x and y.
    distance : (...) ray parameter of the hit (``inf`` on misses).
    view : (..., 3) unit direction from the surface to the eye (``-direction``; also on misses).
    direction : (..., 3) unit ray direction.
    Missed samples have zero geometry.
    """

    hit: np.ndarray
    object_id: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    bitangent: np.ndarray
    uv: np.ndarray
    dudv: np.ndarray
    dpdx: np.ndarray
    dpdy: np.ndarray
    distance: np.ndarray
    view: np.ndarray
    direction: np.ndarray

    @property
    def shape(self) -> tuple[int, ...]:
        return self.hit.shape

    def reshape(self, *shape) -> "GBuffer":
        """The same data with leading shape ``shape`` (e.g. ``-1`` to flatten for shading)."""
        lead = self.hit.ndim
        return GBuffer(**{f.name: getattr(self, f.name).reshape(
            *shape, *getattr(self, f.name).shape[lead:]) for f in fields(self)})

    def select(self, mask) -> "GBuffer":
        """Flat ``(N, ...)`` buffer of the samples where the boolean ``mask (...)`` is true."""
        return GBuffer(**{f.name: getattr(self, f.name)[mask] for f in fields(self)})


# -- rays ------------------------------------------------------------------------------------------


def pixel_positions(camera: Camera, *, jitter=None, offsets=None) -> np.ndarray:
    """Continuous pixel positions ``(x, y)`` of pixel centres plus offsets.

    ``jitter (2,)``: one offset (pixels) for every pixel -> ``(H, W, 2)``.
    ``offsets (S, 2)`` or ``(H, W, S, 2)``: sub-pixel sample offsets from each centre (typically
    in ``[-0.5, 0.5)``) -> ``(H, W, S, 2)``.
    """
    h, w = camera.height, camera.width
    ys, xs = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    centres = np.stack([xs, ys], axis=-1)
    if jitter is not None and offsets is not None:
        raise PrefilterError("jitter, offsets: expected at most one of them")
    if jitter is not None:
        j = as_float_array(jitter, "jitter")
        if j.shape != (2,):
            raise PrefilterError(f"jitter: expected (dx, dy), got shape {j.shape}")
        return centres + j
    if offsets is not None:
        o = as_float_array(offsets, "offsets", ndim_min=2, last_dim=2)
        if o.ndim == 2:
            o = np.broadcast_to(o, (h, w) + o.shape)
        if o.ndim != 4 or o.shape[:2] != (h, w):
            raise PrefilterError(
                f"offsets: expected shape (S, 2) or ({h}, {w}, S, 2), got {o.shape}")
        return centres[:, :, None, :] + o
    return centres


def rays_at(camera: Camera, xy) -> Rays:
    """Primary rays through continuous pixel positions ``xy (..., 2)``, with differentials."""
    xy = as_float_array(xy, "xy", ndim_min=1, last_dim=2)
    r, u, f = camera.basis()
    th = np.tan(np.radians(camera.fov) / 2.0)
    sy = 2.0 * th / camera.height  # image-plane units per pixel (square pixels)
    px = (xy[..., 0:1] - camera.width / 2.0) * sy
    py = (camera.height / 2.0 - xy[..., 1:2]) * sy
    d = f + px * r + py * u
    inv = 1.0 / np.linalg.norm(d, axis=-1, keepdims=True)
    dn = d * inv
    # derivative of d / |d|: (I - dn dn^T) (dd/dx) / |d|, with dd/dx = sy r and dd/dy = -sy u
    ex, ey = sy * r, -sy * u
    ddx = (ex - np.sum(dn * ex, -1, keepdims=True) * dn) * inv
    ddy = (ey - np.sum(dn * ey, -1, keepdims=True) * dn) * inv
    return Rays(np.broadcast_to(camera.origin, dn.shape), dn, ddx, ddy)


def generate_rays(camera: Camera, *, jitter=None, offsets=None) -> Rays:
    """Rays through pixel centres ``(H, W, 3)`` (optionally jittered) or through sub-pixel
    samples ``(H, W, S, 3)``; see :func:`pixel_positions`."""
    return rays_at(camera, pixel_positions(camera, jitter=jitter, offsets=offsets))


# -- intersection ----------------------------------------------------------------------------------


def _empty_gbuffer(shape) -> dict:
    n = int(np.prod(shape, dtype=np.int64))
    return {"hit": np.empty(n, bool), "object_id": np.empty(n, np.int32),
            "position": np.empty((n, 3)), "normal": np.empty((n, 3)), "tangent": np.empty((n, 3)),
            "bitangent": np.empty((n, 3)), "uv": np.empty((n, 2)), "dudv": np.empty((n, 2, 2)),
            "dpdx": np.empty((n, 3)), "dpdy": np.empty((n, 3)), "distance": np.empty(n),
            "view": np.empty((n, 3)), "direction": np.empty((n, 3))}


_ORDER = ("hit", "object_id", "position", "normal", "tangent", "bitangent", "uv", "dudv", "dpdx",
          "dpdy", "distance", "view", "direction")


def _finish(out: dict, shape) -> GBuffer:
    return GBuffer(**{k: v.reshape(tuple(shape) + v.shape[1:]) for k, v in out.items()})


def intersect(scene, rays: Rays) -> GBuffer:
    """Nearest hits of ``rays`` with ``scene.objects`` and the surface data at them."""
    from prefilter.render.kernels import gbuffer_rays_kernel, pack_objects, serial

    d = np.asarray(rays.direction, float)
    shape = d.shape[:-1]

    def flat(a):
        return kernel_array(a, d.shape, np.float64).reshape(-1, 3)

    if any(obj.type == "mesh" for obj in scene.objects):
        from prefilter.render.mesh import trace_objects

        out = trace_objects(scene.objects, flat(rays.origin), flat(d), flat(rays.ddx),
                            flat(rays.ddy))
        return _finish({k: out[k] for k in _ORDER}, shape)
    types, params = pack_objects(scene.objects)
    out = _empty_gbuffer(shape)
    kernel = serial(gbuffer_rays_kernel, len(out["hit"]))
    kernel(flat(rays.origin), flat(d), flat(rays.ddx), flat(rays.ddy), types, params,
           *(out[k] for k in _ORDER))
    return _finish(out, shape)


def camera_params(cam: Camera) -> np.ndarray:
    r, u, f = cam.basis()
    th = np.tan(np.radians(cam.fov) / 2.0)
    return np.concatenate([np.asarray(cam.origin, float), r, u, f,
                           [2.0 * th / cam.height, cam.width, cam.height, 0.0]])


def _gbuffer_camera(scene, cam: Camera, xy: np.ndarray) -> GBuffer:
    """Rays through ``xy (..., 2)`` and their G-buffer in one Numba pass (no ray arrays)."""
    from prefilter.render.kernels import gbuffer_camera_kernel, pack_objects, serial

    if any(obj.type == "mesh" for obj in scene.objects):  # Embree traces the meshes
        return intersect(scene, rays_at(cam, xy))
    shape = xy.shape[:-1]
    types, params = pack_objects(scene.objects)
    out = _empty_gbuffer(shape)
    kernel = serial(gbuffer_camera_kernel, len(out["hit"]))
    kernel(camera_params(cam), np.ascontiguousarray(xy).reshape(-1, 2), types, params,
           *(out[k] for k in _ORDER))
    return _finish(out, shape)


def gbuffer(scene, camera: Camera | None = None, *, jitter=None, offsets=None) -> GBuffer:
    """G-buffer of ``scene`` seen by ``camera`` (default ``scene.camera``).

    Shape ``(H, W)`` at pixel centres (``jitter (2,)`` shifts them all), or ``(H, W, S)`` for
    sub-pixel ``offsets (S, 2)`` / ``(H, W, S, 2)``; see :func:`pixel_positions`.
    """
    cam = scene.camera if camera is None else camera
    return _gbuffer_camera(scene, cam, pixel_positions(cam, jitter=jitter, offsets=offsets))


def gbuffer_at(scene, xy, camera: Camera | None = None) -> GBuffer:
    """G-buffer at arbitrary continuous pixel positions ``xy (..., 2)``."""
    cam = scene.camera if camera is None else camera
    return _gbuffer_camera(scene, cam, as_float_array(xy, "xy", ndim_min=1, last_dim=2))
