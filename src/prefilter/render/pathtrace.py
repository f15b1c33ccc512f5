"""A path tracer over every lobe: next-event estimation with MIS, Russian roulette, shadow rays
and a footprint carried along each path.

Estimator (Veach 1997, ch. 9): at every vertex each light is sampled once (quad lights by
:func:`prefilter.render.lights.light_sample`, environment maps by their texels'
luminance, :class:`EnvironmentSampler`; point and directional lights exactly) and the lobe once
(:meth:`prefilter.lobe.Lobe.sample`, which also continues the path); a light sample and the lobe
sample that reaches the same light are combined by the balance heuristic (eq. 9.13; ``"power"``:
eq. 9.14), per light. Visibility by shadow rays through the scene's intersection code (planes
and spheres by the Numba kernel, meshes by Embree: :func:`prefilter.render.mesh.trace_objects`).
After ``rr_start`` vertices a path survives with probability ``min(0.95, max(throughput))``
(Russian roulette, Arvo and Kirk 1990), its throughput divided by it; ``bounces`` vertices at
most. ``bounces=1`` is the direct light of ``reference`` (with shadows).

Conventions shared with the other methods: pixels whose camera ray misses every object are
black, and lights are not seen by camera rays (only by reflected rays); views below the
shading horizon are clamped (:func:`prefilter.render.shading.local_view`); surfaces are
two-sided.

Footprints: each path carries a ray cone (Amanatides 1984; Akenine-Moeller et al. 2019, "Texture
level of detail strategies for real-time ray tracing") of width ``w`` (world units, across the
ray) and spread ``beta`` (radians; ``beta^2`` is the solid angle of the beam), for *one pixel*:

* camera: the exact ray differentials of the G-buffer at the first hit (Igehy 1999);
  ``beta_0 = sqrt(|dd/dx x dd/dy|)``, ``w_1 = t_1 beta_0``;
* transfer: ``w' = w + beta t`` (Igehy 1999, eq. 8 for a cone); at a hit the footprint is
  that of Igehy's differentials ``beta e_1, beta e_2`` (``e_i`` across the ray) scaled by
  ``w' / (beta t)``, projected on the surface (``g.dudv``: the same footprint type the methods
  read at the first hit);
* a bounce: the surface curvature spreads the beam by ``2 kappa w`` (Igehy 1999, eq. 15 through
  ``dn/dp = kappa``; planes 0, spheres ``1 / r``, meshes the mean of ``|dn| / |dp|`` over their
  edges) and the lobe adds the solid angle its sample represents, ``1 / pdf(wi)`` (Suykens and
  Willems 2001, "Path differentials and applications", sec. 4: a sampled direction's
  differential from its density); solid angles add as the angular variances of covariance
  tracing do (Belcour et al. 2013, eq. 9): ``beta'^2 = (beta + 2 kappa w)^2 + 1 / pdf``.

The footprint is one pixel's: a method that shades ``spp`` samples per pixel divides its area by
``spp`` (the glints paper, sec. 5.3: "the pixel's footprint divided by the sample count").
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.lobe import Lobe
from prefilter.render.camera import GBuffer, gbuffer_at, rays_at
from prefilter.render.driver import (chunk_positions, render_positions, surface_attributes,
                                     with_settings)
from prefilter.render.estimator import HEURISTICS, MaterialLobe, mis_weight
from prefilter.render.lights import LightSet, QuadLight, light_pdf, light_sample
from prefilter.render.mesh import trace_objects
from prefilter.render.shading import local_view
from prefilter.sphere.sampling import to_local, to_world

__all__ = ["EnvironmentSampler", "LobeUnion", "PathOptions", "material_surface",
           "render_path", "render_paths", "trace_paths"]

#: Uniforms a lobe may take per vertex (the glint lobes' hierarchical sampler takes up to 10).
LOBE_DIMS = 12
#: Largest solid angle (sr) a lobe sample adds to the footprint (a hemisphere).
SPREAD_MAX = 2.0 * np.pi
#: Ray origins move off the surface by this much times ``1 + |p|_inf`` (mesh hits are found in
#: float32 by Embree; planes and spheres need none).
OFFSET = 1e-5


@dataclass(frozen=True)
class PathOptions:
    """``bounces``: vertices per path at most (1: direct light only); ``rr_start``: vertices
    before Russian roulette; ``heuristic``: ``"balance"`` or ``"power"``; ``shadows``: trace
    shadow rays (``False`` gives the unshadowed integrand of ``reference``)."""

    bounces: int = 4
    rr_start: int = 3
    heuristic: str = "balance"
    shadows: bool = True

    def __post_init__(self):
        if not (isinstance(self.bounces, int) and 1 <= self.bounces <= 64):
            raise PrefilterError(f"bounces: expected an integer in [1, 64], got {self.bounces!r}")
        if self.heuristic not in HEURISTICS:
            raise PrefilterError(f"heuristic: expected one of {HEURISTICS}, got "
                                 f"{self.heuristic!r}")


# -- lobes over mixed objects ----------------------------------------------------------------------


class LobeUnion(Lobe):
    """Several batched lobes, each over the points of a mask: ``parts = [(mask (N,), lobe)]``,
    the masks disjoint and covering the ``N`` points; results rgb ``(N, 3)``. ``clock``: a dict
    that, when set, accumulates the seconds spent in each part by the part's class name."""

    clock: dict | None = None

    def __init__(self, parts, n: int):
        self.parts = [(np.asarray(m, bool), lobe) for m, lobe in parts]
        self.n = int(n)
        self.n_uniforms = max([lobe.n_uniforms for _, lobe in self.parts] + [2])

    @staticmethod
    def _rgb(v, k):
        v = np.asarray(v, dtype=np.float64)
        return np.broadcast_to(v[:, None], (k, 3)) if v.ndim == 1 else v

    def _run(self, lobe, name, *a):
        t0 = time.perf_counter()
        r = getattr(lobe, name)(*a)
        if self.clock is not None:
            key = type(lobe).__name__
            self.clock[key] = self.clock.get(key, 0.0) + time.perf_counter() - t0
        return r

    def eval(self, wo, wi):
        out = np.zeros((self.n, 3))
        for m, lobe in self.parts:
            out[m] = self._rgb(self._run(lobe, "eval", wo[m], wi[m]), int(m.sum()))
        return out

    def pdf(self, wo, wi):
        out = np.zeros(self.n)
        for m, lobe in self.parts:
            out[m] = self._run(lobe, "pdf", wo[m], wi[m])
        return out

    def sample(self, wo, u):
        wi = np.zeros((self.n, 3))
        wgt = np.zeros((self.n, 3))
        for m, lobe in self.parts:
            w, s = self._run(lobe, "sample", wo[m], u[m][:, :lobe.n_uniforms])
            wi[m] = w
            wgt[m] = self._rgb(s, int(m.sum()))
        return wi, wgt


def material_surface(scene):
    """The renderer's material at hits: ``callable(g, spp) -> (lobe, (t, b, n))`` with the
    level-0 textures (as ``reference``) and :class:`MaterialLobe`; ``g`` a flat G-buffer of hits,
    ``spp`` the samples per pixel (unused: this material does not depend on the footprint)."""

    def at(g, spp):
        a = surface_attributes(scene, g, filtered=False)
        frame = (a["t"], a["b"], a["n"])
        wo = local_view(g.view, *frame)
        return MaterialLobe.for_view(wo, a["alpha_x"], a["alpha_y"], a["base_color"],
                                     a["f0"]), frame

    return at


# -- environment lights ----------------------------------------------------------------------------


def equirect_direction(u, v) -> np.ndarray:
    """World directions ``(..., 3)`` of equirectangular coordinates (``docs/scenes.md``):
    ``(-sin(pi v) sin(2 pi u), cos(pi v), sin(pi v) cos(2 pi u))``."""
    u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
    st = np.sin(np.pi * v)
    return np.stack([-st * np.sin(2 * np.pi * u), np.cos(np.pi * v),
                     st * np.cos(2 * np.pi * u)], -1)


def equirect_uv(d) -> tuple[np.ndarray, np.ndarray]:
    """``(u, v)`` in ``[0, 1)`` x ``[0, 1]`` of unit world directions ``d (..., 3)``."""
    u = (np.arctan2(-d[..., 0], d[..., 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


class EnvironmentSampler:
    """An environment light's radiance (bilinear between texel centres, wrapping in ``u``,
    clamped in ``v``) and a sampler of directions: a texel in proportion to its luminance times
    its solid angle (plus 1e-3 of the mean, so that no texel the bilinear radiance reaches has
    density 0), then uniform in ``(u, v)`` inside it (pbrt-v4's piecewise-constant 2D
    distribution). Density ``p_texel H W / (2 pi^2 sin theta)``."""

    def __init__(self, image, scale: float = 1.0):
        a = np.asarray(image, dtype=np.float64)
        if a.ndim == 2:
            a = a[..., None]
        self.radiance = (np.repeat(a[..., :1], 3, 2) if a.shape[2] < 3 else a[..., :3]) * scale
        h, w = self.radiance.shape[:2]
        self.h, self.w = h, w
        theta = (np.arange(h) + 0.5) * np.pi / h
        lum = self.radiance @ np.array([0.2126, 0.7152, 0.0722])
        mass = lum * np.sin(theta)[:, None]
        mass = mass + 1e-3 * max(float(mass.mean()), 1e-300)
        self.pmf = (mass / mass.sum()).reshape(-1)
        self.cdf = np.cumsum(self.pmf)
        self.cdf[-1] = 1.0

    @classmethod
    def of(cls, light) -> "EnvironmentSampler":
        return cls(light.image.load(), light.scale)

    def eval(self, d) -> np.ndarray:
        """Radiance ``(N, 3)`` towards unit world directions ``d (N, 3)``."""
        u, v = equirect_uv(d)
        x, y = u * self.w - 0.5, np.clip(v * self.h - 0.5, 0.0, self.h - 1.0)
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0 = x0.astype(np.int64) % self.w
        x1 = (x0 + 1) % self.w
        y0 = y0.astype(np.int64)
        y1 = np.minimum(y0 + 1, self.h - 1)
        r = self.radiance
        return ((1 - fy) * ((1 - fx) * r[y0, x0] + fx * r[y0, x1])
                + fy * ((1 - fx) * r[y1, x0] + fx * r[y1, x1]))

    def pdf(self, d) -> np.ndarray:
        """Solid-angle density ``(N,)`` of :meth:`sample` at unit world directions ``d``."""
        u, v = equirect_uv(d)
        i = np.minimum((v * self.h).astype(np.int64), self.h - 1)
        j = np.minimum((u * self.w).astype(np.int64), self.w - 1)
        st = np.sin(np.pi * v)
        p = self.pmf[i * self.w + j] * self.h * self.w / (2 * np.pi * np.pi)
        return np.where(st > 1e-12, p / np.maximum(st, 1e-12), 0.0)

    def sample(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Directions ``(N, 3)`` and densities ``(N,)`` from uniforms ``u (N, 3)``."""
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0], side="right"), self.cdf.size - 1)
        i, j = k // self.w, k % self.w
        uu = (j + u[:, 1]) / self.w
        vv = (i + u[:, 2]) / self.h
        d = equirect_direction(uu, vv)
        return d, self.pdf(d)


# -- geometry helpers ------------------------------------------------------------------------------


def _as_gbuffer(d: dict) -> GBuffer:
    return GBuffer(**d)


def _offset(p, n, d) -> np.ndarray:
    """Ray origins ``(N, 3)``: points ``p`` moved off their surface (geometric normal ``n``) to
    the side the directions ``d`` leave to."""
    side = np.where(np.sum(n * d, -1) >= 0.0, 1.0, -1.0)
    eps = OFFSET * (1.0 + np.max(np.abs(p), axis=-1))
    return p + (side * eps)[:, None] * n


def _trace(objects, o, d, ddx=None, ddy=None) -> dict:
    o = np.ascontiguousarray(o, dtype=np.float64)
    d = np.ascontiguousarray(d, dtype=np.float64)
    z = np.zeros_like(d)
    return trace_objects(objects, o, d, z if ddx is None else np.ascontiguousarray(ddx),
                         z if ddy is None else np.ascontiguousarray(ddy))


def _visible(objects, p, n, d, dist) -> np.ndarray:
    """Shadow rays: ``True (N,)`` where nothing lies between ``p`` and ``p + dist d``."""
    if len(d) == 0:
        return np.zeros(0, bool)
    o = _offset(p, n, d)
    h = _trace(objects, o, d)
    return ~(h["hit"] & (h["distance"] < dist * (1.0 - 1e-7)))


def curvatures(objects) -> np.ndarray:
    """Curvature ``kappa (K,)`` per object for the footprint's spread: 0 for planes, ``1 / r``
    for spheres, for meshes the mean over edges of ``|n_j - n_i| / |p_j - p_i|``."""
    out = np.zeros(len(objects))
    for k, obj in enumerate(objects):
        if obj.type == "sphere":
            out[k] = 1.0 / obj.radius
        elif obj.type == "mesh":
            v, f, nv = obj.data.vertices, obj.data.faces, obj.data.normals
            i, j = f.reshape(-1), np.roll(f, -1, axis=1).reshape(-1)
            dp = np.linalg.norm(v[j] - v[i], axis=-1)
            ok = dp > 0
            out[k] = float(np.mean(np.linalg.norm(nv[j] - nv[i], axis=-1)[ok] / dp[ok])) \
                if np.any(ok) else 0.0
    return out


def _across(d) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(N, 3)`` orthogonal to unit ``d (N, 3)`` and to each other."""
    a = np.where(np.abs(d[:, :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(d, e1)


# -- the estimator ---------------------------------------------------------------------------------


@dataclass
class _Lights:
    quads: tuple          # QuadLight geometry (sampling densities)
    quad_specs: tuple     # QuadLight or TexturedQuad (radiance, texture)
    deltas: LightSet      # point and directional lights
    envs: tuple           # EnvironmentSampler

    @property
    def dims(self) -> int:
        return 2 * len(self.quads) + 3 * len(self.envs)


def scene_lights(scene) -> _Lights:
    """The lights of ``scene`` for :func:`trace_paths` (textured quads included)."""
    from prefilter.render.lighttex import TexturedQuad, _light_texture

    quads, specs, envs = [], [], []
    plain = scene.light_set()
    for i, spec in enumerate(scene.lights):
        if spec.type == "environment":
            try:
                envs.append(EnvironmentSampler.of(spec))
            except PrefilterError as exc:
                raise PrefilterError(f"lights[{i}]: {exc}") from None
        elif spec.type == "quad":
            q = QuadLight(spec.vertices, spec.radiance)
            quads.append(q)
            if getattr(spec, "texture", None) is None:
                specs.append(q)
            else:
                try:
                    specs.append(TexturedQuad(spec.vertices, spec.radiance,
                                              _light_texture(spec.texture)))
                except PrefilterError as exc:
                    raise PrefilterError(f"lights[{i}]: {exc}") from None
    return _Lights(tuple(quads), tuple(specs),
                   LightSet(points=plain.points, directionals=plain.directionals), tuple(envs))


def _emission(spec, points) -> np.ndarray:
    from prefilter.render.reference import light_emission

    return light_emission(spec, points) * spec.radiance


@dataclass
class PathStats:
    """Seconds spent in the surface callback and its lobe per path vertex (index 0: the first
    hit), vertices shaded per depth, and for :class:`LobeUnion` lobes the seconds per lobe class
    per depth (``by_lobe[depth][name]``)."""

    lobe_seconds: list = field(default_factory=list)
    vertices: list = field(default_factory=list)
    by_lobe: list = field(default_factory=list)

    def add(self, depth: int, seconds: float, n: int = 0):
        while len(self.lobe_seconds) <= depth:
            self.lobe_seconds.append(0.0)
            self.vertices.append(0)
            self.by_lobe.append({})
        self.lobe_seconds[depth] += seconds
        self.vertices[depth] += n


class _Vertex(Lobe):
    """A surface's lobe as the path tracer calls it: results rgb ``(N, 3)`` (scalar lobes
    broadcast), each call's time added to ``stats`` at ``depth`` (when given)."""

    def __init__(self, lobe, stats, depth):
        self.lobe, self.stats, self.depth = lobe, stats, depth
        self.n_uniforms = lobe.n_uniforms

    def _call(self, name, *a):
        t0 = time.perf_counter()
        r = getattr(self.lobe, name)(*a)
        if self.stats is not None:
            self.stats.add(self.depth, time.perf_counter() - t0)
        return r

    @staticmethod
    def _rgb(v):
        v = np.asarray(v, dtype=np.float64)
        return np.repeat(v[:, None], 3, 1) if v.ndim == 1 else v

    def eval(self, wo, wi):
        return self._rgb(self._call("eval", wo, wi))

    def pdf(self, wo, wi):
        return self._call("pdf", wo, wi)

    def sample(self, wo, u):
        wi, w = self._call("sample", wo, u)
        return wi, self._rgb(w)


def trace_paths(scene, xy, uniforms, surface, options: PathOptions = PathOptions(), *,
                spp: int = 1, lights: _Lights | None = None,
                stats: PathStats | None = None, min_depth: int = 0) -> np.ndarray:
    """Radiance ``(N, 3)`` of the paths through pixel positions ``xy (N, 2)``.

    Parameters
    ----------
    uniforms : callable(depth) -> (N, D)
        The uniforms of every path at vertex ``depth`` (``D >= LOBE_DIMS + lights.dims + 1``:
        lobe, quad lights (2 each), environments (3 each), Russian roulette).
    surface : callable(g, spp) -> (lobe, (t, b, n))
        The lobe (batched over the hits, rgb or scalar) and its frame at the hits of the flat
        G-buffer ``g``, whose ``dudv`` is the path's footprint of one pixel (the module
        docstring); ``spp``: the samples per pixel, to divide it by.
    min_depth : int
        Light reaching the camera after fewer than ``min_depth`` vertices is dropped (``1``:
        the indirect light only).
    stats : PathStats or None
        Collects the time spent in ``surface`` and its lobe per vertex.
    """
    objects = scene.objects
    lights = scene_lights(scene) if lights is None else lights
    heur = options.heuristic
    n_all = len(xy)
    out = np.zeros((n_all, 3))
    g = gbuffer_at(scene, xy).reshape(-1)
    idx = np.flatnonzero(g.hit)
    if idx.size == 0:
        return out
    g = g.select(g.hit)
    r = rays_at(scene.camera, np.asarray(xy, np.float64)[idx])
    beta = np.sqrt(np.linalg.norm(np.cross(r.ddx, r.ddy), axis=-1))
    width = g.distance * beta
    kappa = curvatures(objects)
    thr = np.ones((idx.size, 3))
    for depth in range(options.bounces):
        u_all = uniforms(depth)
        u = u_all[idx]
        t0 = time.perf_counter()
        lobe, (ts, bs, ns) = surface(g, spp)
        if stats is not None:
            stats.add(depth, time.perf_counter() - t0, idx.size)
            if isinstance(lobe, LobeUnion):
                lobe.clock = stats.by_lobe[depth]
        lobe = _Vertex(lobe, stats, depth)
        wo = local_view(g.view, ts, bs, ns)
        pos, ng = g.position, g.normal
        keep = depth + 1 >= min_depth
        col = LOBE_DIMS
        # -- next-event estimation --
        for q, (geo, spec) in enumerate(zip(lights.quads, lights.quad_specs)):
            uq = u[:, col + 2 * q: col + 2 * q + 2]
            wl, pl, pts = light_sample(geo, pos, uq)
            if keep:
                ok = pl > 0
                wloc = _unit(to_local(wl, ts, bs, ns))
                f = lobe.eval(wo, wloc)
                w = mis_weight(pl, lobe.pdf(wo, wloc), heur)
                ok &= np.any(f > 0, -1) & (w > 0)
                if options.shadows:
                    dist = np.linalg.norm(pts - pos, axis=-1)
                    ok[ok] = _visible(objects, pos[ok], ng[ok], wl[ok], dist[ok])
                if np.any(ok):
                    out[idx[ok]] += (thr[ok] * f[ok] * w[ok, None]
                                     * _emission(spec, pts[ok]))
        col += 2 * len(lights.quads)
        if keep:
            for pl_ in lights.deltas.points:
                dvec = pl_.position - pos
                d2 = np.maximum(np.sum(dvec * dvec, -1), 1e-300)
                wl = dvec / np.sqrt(d2)[:, None]
                out[idx] += _delta(objects, lobe, wo, ts, bs, ns, pos, ng, wl, np.sqrt(d2),
                                   pl_.intensity / d2[:, None], thr, options.shadows)
            for dl in lights.deltas.directionals:
                wl = np.broadcast_to(-dl.direction, pos.shape)
                out[idx] += _delta(objects, lobe, wo, ts, bs, ns, pos, ng, wl,
                                   np.full(len(pos), np.inf), dl.irradiance, thr,
                                   options.shadows)
        for e, env in enumerate(lights.envs):
            ue = u[:, col + 3 * e: col + 3 * e + 3]
            wl, pl = env.sample(ue)
            if keep:
                wloc = _unit(to_local(wl, ts, bs, ns))
                f = lobe.eval(wo, wloc)
                w = mis_weight(pl, lobe.pdf(wo, wloc), heur)
                ok = (pl > 0) & np.any(f > 0, -1) & (w > 0)
                if options.shadows:
                    ok[ok] = _visible(objects, pos[ok], ng[ok], wl[ok], np.inf)
                if np.any(ok):
                    out[idx[ok]] += thr[ok] * f[ok] * w[ok, None] * env.eval(wl[ok])
        col += 3 * len(lights.envs)
        # -- continue the path by the lobe's sample --
        wloc, weight = lobe.sample(wo, u[:, :LOBE_DIMS][:, :lobe.n_uniforms])
        wloc = _unit(wloc)
        pb = lobe.pdf(wo, wloc)
        wi = _unit(to_world(wloc, ts, bs, ns))
        thr = thr * weight
        alive = (pb > 0) & np.any(thr > 0, -1)
        if depth + 1 >= options.rr_start:
            q_s = np.minimum(0.95, np.max(thr, -1))
            alive &= u[:, col] < q_s
            thr = thr / np.where(alive, q_s, 1.0)[:, None]
        # the footprint through the bounce: curvature and the lobe's solid angle
        beta = np.sqrt((beta + 2.0 * kappa[g.object_id] * width) ** 2
                       + np.minimum(1.0 / np.maximum(pb, 1e-300), SPREAD_MAX))
        sel = np.flatnonzero(alive)
        if sel.size == 0:
            break
        idx, thr, beta, width, pb = idx[sel], thr[sel], beta[sel], width[sel], pb[sel]
        pos, ng, wi = pos[sel], ng[sel], wi[sel]
        e1, e2 = _across(wi)
        h = _trace(objects, _offset(pos, ng, wi), wi, beta[:, None] * e1, beta[:, None] * e2)
        # light reached by the lobe's sample (the light strategy's density for MIS)
        if depth + 2 >= min_depth:
            for geo, spec in zip(lights.quads, lights.quad_specs):
                p_l, pts = light_pdf(geo, pos, wi)
                reach = (p_l > 0) & (np.linalg.norm(pts - pos, axis=-1) < h["distance"])
                if np.any(reach):
                    wb = mis_weight(pb[reach], p_l[reach], heur) * pb[reach]
                    out[idx[reach]] += thr[reach] * wb[:, None] * _emission(spec, pts[reach])
            miss = ~h["hit"]
            if lights.envs and np.any(miss):
                for env in lights.envs:
                    p_e = env.pdf(wi[miss])
                    wb = mis_weight(pb[miss], p_e, heur) * pb[miss]
                    out[idx[miss]] += thr[miss] * wb[:, None] * env.eval(wi[miss])
        hit = h["hit"]
        if depth + 1 == options.bounces or not np.any(hit):
            break
        g = _as_gbuffer({k: v[hit] for k, v in h.items()})
        idx, thr, beta, width = idx[hit], thr[hit], beta[hit], width[hit]
        # the cone's width at the hit; Igehy's footprint of (beta e1, beta e2) scaled to it
        t_hit = g.distance
        width = width + beta * t_hit
        s = width / np.maximum(beta * t_hit, 1e-300)
        g.dudv *= s[:, None, None]
        g.dpdx *= s[:, None]
        g.dpdy *= s[:, None]
    return out


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _delta(objects, lobe, wo, ts, bs, ns, pos, ng, wl, dist, e, thr, shadows) -> np.ndarray:
    """Throughput times the lobe at a delta light's direction ``wl`` times its irradiance ``e``
    (with a shadow ray)."""
    f = lobe.eval(wo, _unit(to_local(wl, ts, bs, ns)))
    c = thr * f * e
    if shadows:
        ok = np.any(c > 0, -1)
        vis = np.zeros(len(c), bool)
        vis[ok] = _visible(objects, pos[ok], ng[ok], np.ascontiguousarray(wl[ok]), dist[ok])
        c = c * vis[:, None]
    return c


# -- the render method -----------------------------------------------------------------------------


def path_options(settings) -> PathOptions:
    """:class:`PathOptions` from a method's settings (``--param bounces=N``)."""
    return PathOptions(bounces=int(settings.param("bounces", str(PathOptions.bounces))))


def render_paths(scene, settings, surface, options: PathOptions, *, desc: str = "path",
                 stats: PathStats | None = None, min_depth: int = 0) -> np.ndarray:
    """Drive :func:`trace_paths` over the image: ``settings.spp`` stratified sub-pixel positions
    per pixel, the uniforms of each vertex drawn per image row (``SeedSequence(seed,
    spawn_key=(row, 1 + depth))``), so images do not depend on the chunk size.
    Returns ``(H, W, 3)`` float64."""
    lights = scene_lights(scene)
    dims = LOBE_DIMS + lights.dims + 1
    spp = settings.spp
    settings = with_settings(settings, chunk_samples=min(settings.chunk_samples, 1 << 15))

    def positions(rows, w):
        xy, _ = chunk_positions(settings, rows, w, True)
        return xy, list(rows)

    def radiance(xy, rows):
        per_row = len(xy) // len(rows)

        def uniforms(depth):
            return np.concatenate([
                np.random.default_rng(np.random.SeedSequence(
                    settings.seed, spawn_key=(int(y), 1 + depth))).random((per_row, dims))
                for y in rows])

        return trace_paths(scene, xy, uniforms, surface, options, spp=spp, lights=lights,
                           stats=stats, min_depth=min_depth)

    return render_positions(scene, settings, radiance, desc=desc, positions=positions)


def render_path(scene, settings) -> np.ndarray:
    """The ``path`` method: :func:`render_paths` with the renderer's material
    (:func:`material_surface`), ``--param bounces=N`` vertices per path (default 4)."""
    return render_paths(scene, settings, material_surface(scene), path_options(settings))

