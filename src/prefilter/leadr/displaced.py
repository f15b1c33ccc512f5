"""Ground truth for LEADR: the displaced microsurface itself, by exact height-field ray marching.

The surface is the bilinear interpolation ``z = h(x, y)`` of a periodic height grid (texel
units, texel ``(i, j)`` at ``x = j, y = i``). Its slopes are the bilinear patches' gradients, whose
moments over a cell are closed-form (:func:`cell_moments`), so LEADR statistics of any block of
cells are exact (moments are linear: a block is the box average of its cells).

:func:`displaced_radiance` averages, over parallel view rays through a uniform grid of points of a
block of the mean plane (radiance per projected area, as LEADR defines it), the radiance of the
first hit lit by a directional light, with a shadow ray: masking and shadowing come from the
geometry. :func:`normal_mapped_radiance` shades the same block's normals without geometry, and
:func:`naive_radiance` shades the block's single mip-averaged normal. Own Numba ray marcher (no
external ray tracer is installed; a height field needs none).
"""

from __future__ import annotations

import numpy as np

from prefilter.jit import kernel_array, njit_parallel, njit_serial, prange
from prefilter.validation import as_directions, as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.microfacet import Beckmann


@njit_parallel
def march(h, ox, oy, oz, dx, dy, dz, hmin, hmax, step, max_steps):  # pragma: no cover
    """Parameter ``t >= 0`` of the first hit of rays ``o + t d`` with the bilinear height field,
    ``inf`` if the ray leaves the slab ``[hmin, hmax]`` first (fixed steps, then bisection)."""
    n = ox.size
    ny, nx = h.shape
    out = np.empty(n)
    for r in prange(n):
        res = np.inf
        if oz[r] - _bilerp(h, ox[r], oy[r], ny, nx) <= 0.0:
            res = 0.0
        else:
            t0 = 0.0
            for _ in range(max_steps):
                t1 = t0 + step
                z1 = oz[r] + t1 * dz[r]
                f1 = z1 - _bilerp(h, ox[r] + t1 * dx[r], oy[r] + t1 * dy[r], ny, nx)
                if f1 <= 0.0:
                    a, b = t0, t1
                    for _k in range(40):
                        m = 0.5 * (a + b)
                        fm = oz[r] + m * dz[r] - _bilerp(h, ox[r] + m * dx[r],
                                                         oy[r] + m * dy[r], ny, nx)
                        if fm > 0.0:
                            a = m
                        else:
                            b = m
                    res = 0.5 * (a + b)
                    break
                if (dz[r] < 0.0 and z1 < hmin) or (dz[r] > 0.0 and z1 > hmax):
                    break
                t0 = t1
        out[r] = res
    return out


@njit_serial
def _bilerp(h, x, y, ny, nx):  # pragma: no cover - compiled
    fx = np.floor(x)
    fy = np.floor(y)
    tx = x - fx
    ty = y - fy
    j0 = int(fx) % nx
    i0 = int(fy) % ny
    j1 = (j0 + 1) % nx
    i1 = (i0 + 1) % ny
    return ((h[i0, j0] * (1 - tx) + h[i0, j1] * tx) * (1 - ty)
            + (h[i1, j0] * (1 - tx) + h[i1, j1] * tx) * ty)


def gradient(h, x, y):
    """Bilinear gradient ``(..., 2)`` at points ``x, y`` (periodic)."""
    ny, nx = h.shape
    fx, fy = np.floor(x), np.floor(y)
    tx, ty = x - fx, y - fy
    j0, i0 = fx.astype(np.int64) % nx, fy.astype(np.int64) % ny
    j1, i1 = (j0 + 1) % nx, (i0 + 1) % ny
    h00, h01, h10, h11 = h[i0, j0], h[i0, j1], h[i1, j0], h[i1, j1]
    sx = (h01 - h00) * (1 - ty) + (h11 - h10) * ty
    sy = (h10 - h00) * (1 - tx) + (h11 - h01) * tx
    return np.stack([sx, sy], -1)


def cell_moments(height) -> np.ndarray:
    """Exact slope moments ``(H, W, 5)`` of each bilinear cell (cell ``(i, j)`` spans texels
    ``i..i+1, j..j+1``): ``sx = a (1 - y) + b y``, ``sy = c (1 - x) + d x`` give
    ``E[sx^2] = (a^2 + ab + b^2) / 3``, ``E[sx sy] = (a + b)(c + d) / 4``."""
    h = as_float_array(height, "height", ndim_min=2)
    r = lambda a, k, ax: np.roll(a, -k, axis=ax)  # noqa: E731
    a = r(h, 1, 1) - h
    b = r(a, 1, 0)
    c = r(h, 1, 0) - h
    d = r(c, 1, 1)
    return np.stack([(a + b) / 2, (c + d) / 2, (a * a + a * b + b * b) / 3,
                     (c * c + c * d + d * d) / 3, (a + b) * (c + d) / 4], -1)


def block_points(i0: int, j0: int, block: int, k: int):
    """``k x k`` stratified-centre points of the block whose first cell is ``(i0, j0)``."""
    u = (np.arange(k) + 0.5) / k * block
    y, x = np.meshgrid(i0 + u, j0 + u, indexing="ij")
    return x.ravel(), y.ravel()


def micro(wo, wi, n, sigma_b, albedo, specular):
    """Cosine-weighted micro BRDF at unit normals ``n (N, 3)``: Lambert or isotropic centred
    Beckmann of slope std ``sigma_b`` around ``n`` (both directions expressed in n's frame)."""
    if not specular:
        return albedo / np.pi * np.maximum(np.sum(n * wi, -1), 0.0) * (np.sum(n * wo, -1) > 0)
    t = np.cross(n, np.array([0.0, 1.0, 0.0]))
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(n, t)
    loc = lambda w: np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)  # noqa
    lo, li = loc(np.broadcast_to(wo, n.shape)), loc(np.broadcast_to(wi, n.shape))
    ok = (lo[:, 2] > 1e-9) & (li[:, 2] > 1e-9)
    val = np.zeros(len(n))
    if np.any(ok):
        model = Beckmann.isotropic(np.sqrt(2.0) * sigma_b)
        val[ok] = model.eval(lo[ok], li[ok])
    return val


def normals(s):
    """Unit normals ``(..., 3)`` of slopes ``s (..., 2)``: ``normalize(-s_x, -s_y, 1)``."""
    n = np.concatenate([-s, np.ones(s.shape[:-1] + (1,))], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def displaced_radiance(height, block: int, i0: int, j0: int, wo, wi, *, k: int = 64,
                       sigma_b: float = 0.1, albedo: float = 1.0, specular: bool = True,
                       shadowing: bool = True, step: float = 0.1) -> float:
    """Radiance towards ``wo`` of a block of the displaced surface under a unit directional
    light from ``wi`` (per projected area of the block, ``k x k`` parallel view rays)."""
    h = np.ascontiguousarray(as_float_array(height, "height", ndim_min=2))
    wo = as_directions(wo, "wo")
    wi = as_directions(wi, "wi")
    if wo[2] <= 0.05:
        raise PrefilterError(f"wo: expected a view above the mean plane (z > 0.05), got {wo}")
    k = as_positive_int(k, "k")
    x, y = block_points(i0, j0, block, k)
    hmax, hmin = float(h.max()), float(h.min())
    # Start each ray above every height, on the line through the mean-plane point along wo.
    t_up = (hmax + 1e-6) / wo[2]
    ox, oy, oz = x + t_up * wo[0], y + t_up * wo[1], np.full(x.shape, hmax + 1e-6)
    d = -wo
    dn = step / max(np.hypot(d[0], d[1]), abs(d[2]))
    max_steps = int(4 * (h.shape[0] + h.shape[1]) / step) + 16
    t = march(h, ox, oy, oz, np.full(x.shape, d[0]), np.full(x.shape, d[1]),
               np.full(x.shape, d[2]), hmin, hmax + 1e-3, dn, max_steps)
    hit = np.isfinite(t)
    px, py, pz = ox + t * d[0], oy + t * d[1], oz + t * d[2]
    n = normals(gradient(h, px, py))
    val = micro(wo, wi, n, sigma_b, albedo, specular)
    if shadowing:
        lit = np.ones(x.shape, bool)
        cand = hit & (val > 0)
        if np.any(cand) and wi[2] > 0.0:
            eps = 1e-4
            sx, sy, sz = px[cand] + eps * wi[0], py[cand] + eps * wi[1], pz[cand] + eps * wi[2]
            dn_i = step / max(np.hypot(wi[0], wi[1]), abs(wi[2]))
            ts = march(h, sx, sy, sz, np.full(sx.shape, wi[0]), np.full(sx.shape, wi[1]),
                        np.full(sx.shape, wi[2]), hmin - 1.0, hmax, dn_i, max_steps)
            lit[cand] = ~np.isfinite(ts)
        val = val * lit
    return float(np.mean(np.where(hit, val, 0.0)))


def normal_mapped_radiance(height, block: int, i0: int, j0: int, wo, wi, *, k: int = 64,
                           sigma_b: float = 0.1, albedo: float = 1.0,
                           specular: bool = True) -> float:
    """The same block shaded by its normals on the flat mean plane (no masking or shadowing by
    the geometry), averaged uniformly over the block."""
    h = as_float_array(height, "height", ndim_min=2)
    x, y = block_points(i0, j0, block, k)
    n = normals(gradient(h, x, y))
    return float(np.mean(micro(as_directions(wo, "wo"), as_directions(wi, "wi"), n, sigma_b,
                                albedo, specular)))


def naive_radiance(height, block: int, i0: int, j0: int, wo, wi, *, k: int = 64,
                   sigma_b: float = 0.1, albedo: float = 1.0, specular: bool = True) -> float:
    """Naive mip-mapped normal mapping: one normal, the normalised block average of the normals,
    with the micro roughness only."""
    h = as_float_array(height, "height", ndim_min=2)
    x, y = block_points(i0, j0, block, k)
    nbar = normals(gradient(h, x, y)).mean(axis=0)
    nbar /= np.linalg.norm(nbar)
    return float(micro(as_directions(wo, "wo"), as_directions(wi, "wi"), nbar[None], sigma_b,
                        albedo, specular)[0])


# -- environment lighting ------------------------------------------------------------------------


class EnvSampler:
    """Importance sampling of a lat-long :class:`prefilter.leadr.envmap.EnvMap` (level 0, in the
    surface's local frame): texel ``t`` with probability ``0.9 lum_t Omega_t / sum lum Omega +
    0.1 Omega_t / 4 pi`` (the uniform part keeps the density positive everywhere), then a
    uniform direction in the texel's solid angle; density ``P_t / Omega_t``."""

    def __init__(self, env):
        from prefilter.leadr.envmap import texel_directions

        a = env.levels[0]
        self.h, self.w = a.shape[:2]
        _, omega = texel_directions(self.h, self.w)
        lum = a.mean(axis=-1) * omega
        p = 0.9 * lum / max(lum.sum(), 1e-300) + 0.1 * omega / omega.sum()
        self.p = p.ravel() / p.sum()
        self.cdf = np.cumsum(self.p)
        self.omega = omega.ravel()
        self.cos_edges = np.cos(np.linspace(0.0, np.pi, self.h + 1))

    def sample(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Directions ``(M, 3)`` and densities ``(M,)`` from uniforms ``u (M, 3)``."""
        t = np.minimum(np.searchsorted(self.cdf, u[:, 0] * self.cdf[-1], side="right"),
                       self.p.size - 1)
        i, j = np.divmod(t, self.w)
        ct = self.cos_edges[i] + u[:, 1] * (self.cos_edges[i + 1] - self.cos_edges[i])
        phi = (j + u[:, 2]) * 2.0 * np.pi / self.w
        st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
        d = np.stack([st * np.cos(phi), st * np.sin(phi), ct], -1)
        return d, self.p[t] / self.omega[t]

    def pdf(self, d) -> np.ndarray:
        """Density ``(M,)`` of directions ``d (M, 3)``."""
        from prefilter.leadr.envmap import direction_to_uv

        uv = direction_to_uv(d)
        i = np.minimum((uv[:, 1] * self.h).astype(np.int64), self.h - 1)
        j = np.minimum((uv[:, 0] * self.w).astype(np.int64), self.w - 1)
        t = i * self.w + j
        return self.p[t] / self.omega[t]


def _frames(n):
    t = np.cross(n, np.array([0.0, 1.0, 0.0]))
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return t, np.cross(n, t)


def env_estimates(env, sampler, wo, n, spp, rng, sigma_b, albedo, specular, visible=None,
                   rot=None):
    """MIS estimates ``(P, C)`` of ``integral L(wi) f(wo, wi) <n, wi> V(p, wi) dwi`` at points with
    unit normals ``n (P, 3)`` seen from ``wo (3,)`` or ``(P, 3)``: ``spp / 2`` pairs of a micro-BRDF
    sample (Beckmann VNDF or cosine) and an environment sample, balance heuristic
    (:func:`prefilter.render.estimator.mis_directions`), from a scrambled Sobol set per point
    (:func:`prefilter.render.estimator.owen_sobol`, seeded by ``rng``).
    ``visible(idx, wi) -> bool`` tests shadow rays of point ``idx`` (``None``: no shadowing);
    ``rot (3, 3)`` maps local directions to the map's coordinates (``None``: identity)."""
    from prefilter.render.estimator import Lambert, mis_directions, owen_sobol

    p = len(n)
    half = max(1, spp // 2)
    t, b = _frames(n)
    idx = np.repeat(np.arange(p), half)
    tq, bq, nq = t[idx], b[idx], n[idx]

    def loc(w):
        return np.stack([np.sum(w * tq, -1), np.sum(w * bq, -1), np.sum(w * nq, -1)], -1)

    def world(li):
        return li[:, :1] * tq + li[:, 1:2] * bq + li[:, 2:] * nq

    def to_map(w):
        return w if rot is None else w @ rot.T

    lo = loc(np.broadcast_to(wo, (p, 3))[idx])
    seen = lo[:, 2] > 1e-9
    lo = np.where(seen[:, None], lo, [0.0, 0.0, 1.0])  # views below a micro normal: no light
    lobe = Beckmann.isotropic(np.sqrt(2.0) * sigma_b) if specular else Lambert(albedo)
    # each point's pairs: a scrambled Sobol set over (lobe 2, environment 3) dimensions
    u = owen_sobol(np.arange(p), half, 5, int(rng.integers(1 << 32)), 0).reshape(-1, 5)
    u_b = u[:, :2]
    wi_e, _ = sampler.sample(u[:, 2:])
    p_e = sampler.pdf(wi_e)
    if rot is not None:
        wi_e = wi_e @ rot  # map -> local (rot is orthogonal)
    t_e, li_b, t_b = mis_directions(lobe, lo, loc(wi_e), p_e,
                                    lambda li: sampler.pdf(to_map(world(li))), u_b)
    all_idx = np.concatenate([idx, idx])
    wi = np.concatenate([world(li_b), wi_e])
    val = np.concatenate([t_b, t_e]) * np.concatenate([seen, seen])
    if visible is not None:
        cand = val > 0
        vis = np.zeros(len(wi), bool)
        vis[cand] = visible(all_idx[cand], wi[cand])
        val = val * vis
    rad = np.zeros((len(wi), env.levels[0].shape[2]))
    nz = val > 0
    rad[nz] = env.lookup(to_map(wi[nz]), 0.0) * val[nz, None]
    out = np.zeros((p, rad.shape[1]))
    np.add.at(out, all_idx, rad)
    return out / half


def _first_hits(height, x, y, wo, step):
    """March the view rays through the mean-plane points ``x, y (P,)`` towards ``wo``: the
    height ``h``, the views ``(P, 3)``, ``hit (P,)`` and the hit points ``(px, py, pz)``."""
    h = np.ascontiguousarray(as_float_array(height, "height", ndim_min=2))
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    wo = kernel_array(as_directions(wo, "wo"), (x.size, 3))
    if np.any(wo[:, 2] <= 0.05):
        raise PrefilterError("wo: expected views above the mean plane (z > 0.05), got "
                             f"min z = {wo[:, 2].min():.3g}")
    hmax, hmin = float(h.max()), float(h.min())
    # Start each ray above every height, on the line through the mean-plane point along wo.
    t_up = (hmax + 1e-6) / wo[:, 2]
    ox, oy, oz = x + t_up * wo[:, 0], y + t_up * wo[:, 1], np.full(x.shape, hmax + 1e-6)
    d = np.ascontiguousarray(-wo)
    dn = step / float(np.min(np.maximum(np.hypot(d[:, 0], d[:, 1]), np.abs(d[:, 2])))) \
        if x.size else step
    t = march(h, ox, oy, oz, np.ascontiguousarray(d[:, 0]), np.ascontiguousarray(d[:, 1]),
               np.ascontiguousarray(d[:, 2]), hmin, hmax + 1e-3, dn, _max_steps(h, step))
    hit = np.isfinite(t)
    return h, wo, hit, tuple((o + t * d[:, k])[hit] for k, o in enumerate((ox, oy, oz)))


def _max_steps(h, step) -> int:
    return int(4 * (h.shape[0] + h.shape[1]) / step) + 16


def _shadow_rays_escape(h, px, py, pz, wi, step) -> np.ndarray:
    """``(Q,)``: whether the shadow rays from the hit points ``p`` towards ``wi (Q, 3)`` leave
    the height field ``h``."""
    eps = 1e-4
    dn_i = step / np.maximum(np.hypot(wi[:, 0], wi[:, 1]), np.abs(wi[:, 2]))
    # one step length for all rays: the smallest (safe) one
    ts = march(h, px + eps * wi[:, 0], py + eps * wi[:, 1], pz + eps * wi[:, 2],
               np.ascontiguousarray(wi[:, 0]), np.ascontiguousarray(wi[:, 1]),
               np.ascontiguousarray(wi[:, 2]), float(h.min()) - 1.0, float(h.max()),
               float(dn_i.min()), _max_steps(h, step))
    return ~np.isfinite(ts)


def displaced_env_points(height, x, y, wo, env, *, rot=None, spp: int = 8,
                         sigma_b: float = 0.1, albedo: float = 1.0, specular: bool = True,
                         shadowing: bool = True, step: float = 0.1, seed: int = 0) -> np.ndarray:
    """Radiance ``(P, C)`` of the displaced surface along the rays that cross the mean plane at
    texel coordinates ``x, y (P,)`` towards the viewer ``wo (3,)`` or ``(P, 3)`` (local frame, z
    = mean-plane normal), lit by ``env`` (``rot (3, 3)``: local -> map coordinates).

    Each ray is marched from above the highest bump down to its first hit (masking by the
    geometry); the hit's reflected radiance is estimated with ``spp`` MIS samples (micro BRDF and
    environment, balance heuristic), each with a shadow ray against the height field
    (``shadowing``). Single scattering; seeded.
    """
    from prefilter.leadr.envmap import EnvMap

    if not isinstance(env, EnvMap):
        raise PrefilterError(f"env: expected a prefilter.leadr.envmap.EnvMap, got {type(env)}")
    spp = as_positive_int(spp, "spp", lo=2)
    rng = np.random.default_rng(seed)
    h, wo, hit, (px, py, pz) = _first_hits(height, x, y, wo, step)
    n = normals(gradient(h, px, py))

    def visible(q, wi):
        return _shadow_rays_escape(h, px[q], py[q], pz[q], wi, step)

    out = np.zeros((hit.size, env.levels[0].shape[2]))
    out[hit] = env_estimates(env, EnvSampler(env), wo[hit], n, spp, rng, sigma_b, albedo,
                              specular, visible if shadowing else None,
                              None if rot is None else np.asarray(rot, np.float64))
    return out


def displaced_env_radiance(height, block: int, i0: int, j0: int, wo, env, *, k: int = 48,
                           spp: int = 8, sigma_b: float = 0.1, albedo: float = 1.0,
                           specular: bool = True, shadowing: bool = True, step: float = 0.1,
                           seed: int = 0) -> np.ndarray:
    """Radiance ``(C,)`` towards ``wo`` of a block of the displaced surface lit by the
    environment ``env`` (an :class:`~prefilter.leadr.envmap.EnvMap` whose z axis is the mean
    plane's normal), per projected area of the block: the mean of
    :func:`displaced_env_points` over ``k x k`` parallel view rays through the block.

    At each first hit (masking by the geometry) ``spp`` directions estimate the reflected
    radiance by multiple importance sampling (balance heuristic) of the micro BRDF (Beckmann
    visible normals or cosine) and of the environment (luminance-weighted texels), each with a
    shadow ray against the height field (``shadowing``). Single scattering: no
    interreflections. Seeded: same inputs, same bytes.
    """
    k = as_positive_int(k, "k")
    x, y = block_points(i0, j0, block, k)
    return displaced_env_points(height, x, y, wo, env, spp=spp, sigma_b=sigma_b, albedo=albedo,
                                specular=specular, shadowing=shadowing, step=step,
                                seed=seed).mean(axis=0)


def normal_mapped_env_radiance(height, block: int, i0: int, j0: int, wo, env, *, k: int = 48,
                               spp: int = 8, sigma_b: float = 0.1, albedo: float = 1.0,
                               specular: bool = True, seed: int = 0) -> np.ndarray:
    """The block's normals on the flat mean plane under ``env`` (no masking or shadowing by the
    geometry), same estimator as :func:`displaced_env_radiance`; ``(C,)``."""
    h = as_float_array(height, "height", ndim_min=2)
    x, y = block_points(i0, j0, block, k)
    n = normals(gradient(h, x, y))
    est = env_estimates(env, EnvSampler(env), as_directions(wo, "wo"), n, spp,
                         np.random.default_rng(seed), sigma_b, albedo, specular)
    return est.mean(axis=0)


def naive_env_radiance(height, block: int, i0: int, j0: int, wo, env, *, k: int = 48,
                       samples: int = 1 << 15, sigma_b: float = 0.1, albedo: float = 1.0,
                       specular: bool = True, seed: int = 0) -> np.ndarray:
    """Naive mip-mapped normal mapping under ``env``: the normalised block average of the normals
    with the micro BRDF only (``samples`` MIS samples); ``(C,)``."""
    h = as_float_array(height, "height", ndim_min=2)
    x, y = block_points(i0, j0, block, k)
    nbar = normals(gradient(h, x, y)).mean(axis=0)
    nbar /= np.linalg.norm(nbar)
    est = env_estimates(env, EnvSampler(env), as_directions(wo, "wo"), nbar[None], samples,
                         np.random.default_rng(seed), sigma_b, albedo, specular)
    return est[0]


# -- point and directional lights, per ray ---------------------------------------------------------


def trace_points(height, x, y, wo, wi=None, *, shadowing: bool = True, step: float = 0.1):
    """First hits of the view rays that cross the mean plane at texel coordinates ``x, y (P,)``
    towards ``wo (P, 3)`` (local frame, z = mean-plane normal), and their shadow rays towards
    ``wi (P, 3)`` (a point light seen from each hit, or a directional light).

    Returns ``hit (P,)`` bool, unit micro-surface normals ``n (P, 3)`` at the hits (zero where
    nothing is hit) and ``lit (P,)`` (``True`` where the shadow ray leaves the height field, or
    everywhere if ``wi`` is ``None`` or ``shadowing`` is off). Directions below the mean plane are
    never lit (a shadow ray going down always meets the periodic height field).
    """
    h, wo, hit, (px, py, pz) = _first_hits(height, x, y, wo, step)
    n = np.zeros((hit.size, 3))
    n[hit] = normals(gradient(h, px, py))
    lit = np.ones(hit.size, bool)
    if wi is not None and shadowing:
        wi = np.broadcast_to(as_directions(wi, "wi"), (hit.size, 3))[hit]
        up = wi[:, 2] > 0.0
        lit_h = np.zeros(len(wi), bool)
        if np.any(up):
            lit_h[up] = _shadow_rays_escape(h, px[up], py[up], pz[up], wi[up], step)
        lit[hit] = lit_h
    return hit, n, lit


def displaced_point_radiance(height, x, y, wo, wi, *, sigma_b: float = 0.1, albedo: float = 1.0,
                             specular: bool = True, shadowing: bool = True,
                             step: float = 0.1) -> np.ndarray:
    """Cosine-weighted micro BRDF ``f(wo, wi) <n, wi> V(wi)`` at the first hit of each view ray
    (:func:`trace_points`), ``(P,)``: the radiance of the displaced surface per unit irradiance
    (at normal incidence) of a point or directional light from ``wi (P, 3)``; 0 where the ray
    misses. Masking by the first hit, shadowing by a shadow ray (``shadowing``)."""
    hit, n, lit = trace_points(height, x, y, wo, wi, shadowing=shadowing, step=step)
    wo = np.broadcast_to(as_directions(wo, "wo"), n.shape)
    wi = np.broadcast_to(as_directions(wi, "wi"), n.shape)
    out = np.zeros(len(n))
    if np.any(hit):
        out[hit] = micro(wo[hit], wi[hit], n[hit], sigma_b, albedo, specular) * lit[hit]
    return out


def normal_mapped_point_radiance(height, x, y, wo, wi, *, sigma_b: float = 0.1,
                                 albedo: float = 1.0, specular: bool = True) -> np.ndarray:
    """The height field's normal at ``x, y (P,)`` on the flat mean plane (no parallax, masking or
    shadowing by the geometry) with the micro BRDF: ``f(wo, wi) <n, wi>``, ``(P,)``."""
    h = as_float_array(height, "height", ndim_min=2)
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    n = normals(gradient(h, x, y))
    wo = np.broadcast_to(as_directions(wo, "wo"), n.shape)
    wi = np.broadcast_to(as_directions(wi, "wi"), n.shape)
    return micro(wo, wi, n, sigma_b, albedo, specular)
