"""The ``glints-wang`` render method: glints on an unbounded, non-periodic Wang tiling.

A material's ``normal_map`` is the *exemplar*: the method synthesises 16 Wang tiles from it
(:func:`prefilter.glints.wang.synthesize`, :data:`WANG_SETTINGS`), bakes their per-tile
footprint pyramids (:func:`prefilter.glints.wang_ndf.bake_tiles`, CP-compressed) once and
caches them on disk next to the ``glints`` bakes (:func:`prefilter.glints.bake.cache_dir`,
``wang-<SHA-1 of the normals>-<SHA-1 of the settings and store version>.npz``,
:mod:`~prefilter.glints.wang_store` format, 8-bit factor codes by default, written atomically
under a lock; the render uses the pyramids loaded from the file, their codes packed for the
query kernels, also in the baking process). The surface is the implicit tiling of the plane
(hashing, glints paper sec. 5.5): constant storage whatever the area the frame covers.

Texel scale: one texel of the tiling per texel of the exemplar (the footprints of
:func:`prefilter.glints.render.footprints` on the exemplar's shape), so ``glints-wang`` and
``glints-direct`` see the same footprints.

Point and directional lights: the glint BRDF ``F G D / (4 wo_z)`` (paper eq. 1) with ``D`` the
footprint NDF of the tiling at the half vector (:func:`prefilter.glints.wang_ndf.ndf_points`:
direct P-NDF below ``min_sigma``, per-tile pyramids, tile-type shares, expected tiling), one
batched Numba query for all samples and lights of an object. Diffuse: Lambert with
``base_color``.

Environment lights: the SG light samples of ``glints``
(:func:`prefilter.glints.render.environment_sgs` fit, ``ENV_SAMPLES`` samples per shading
sample drawn with :func:`prefilter.glints.envlight.sample_sg` from the
:func:`prefilter.glints.render.random_dims` uniforms: the same directions as ``glints`` and
``glints-direct`` for a seed), the NDF prefiltered over each lobe's epsilon-support
(``ENV_EPS``; glints paper sec. 5.4, as ``glints``) by range queries across tile borders
(:func:`prefilter.glints.wang_range.ndf_ranges`), the point NDF below ``min_sigma``.
Untextured quad lights: range queries over the light's half-vector patches
(:func:`quad_range_wang`, the patches of :func:`prefilter.glints.render.quad_patches`, as
``glints``) where they apply; elsewhere light sampling (:data:`QUAD_SAMPLES` uniform points on
the light's area; no MIS); diffuse by Lambert's polygon formula. The point NDF at the half
vectors of every remaining sample of every light of an object comes from one
:func:`prefilter.glints.wang_ndf.ndf_points` call. Textured quads are rejected.
"""

from __future__ import annotations

import json
import os

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.glints.pndf import DEFAULT_ROUGHNESS, as_normal_map, map_digest
from prefilter.glints.wang_ndf import TiledNDF, ndf_points

#: Tiles and bake of the render cache. ``tile`` 32 (the CLI's default), or the exemplar's size
#: (even, >= 4) when it is smaller (:func:`tile_size`); ``intrinsic_roughness``, ``support``:
#: those of ``glints`` (:data:`prefilter.glints.bake.BAKE_SETTINGS`, whole disk of half
#: vectors); ``ndf_res`` 256 (pixel 0.78 intrinsic stds, as ``glints``): at 128 the FLIP against
#: ``glints-direct`` on the assembled map is 0.127 instead of 0.074 at mid distance; the cost
#: is the bake (docs/glints-wang.md, "Not done / limits": minutes, GiB of peak RSS) at
#: ``rank`` 16 with ``block`` 16. ``bilinear``: NDF values
#: interpolated between pixel centres, the pyramids baked with
#: :func:`prefilter.glints.bake.bilinear_bake_roughness` (the interpolation's blur restores the
#: intrinsic roughness), the texels evaluated at query time as point densities
#: (:func:`prefilter.glints.wang_ndf.ndf_points`); the pixel's value instead: FLIP 0.167 /
#: 0.120 / 0.104 instead of 0.004 / 0.029 / 0.027 (tests/glints/test_wang_render.py scene).
#: ``wide_tiles`` 0.5 (per-tile pyramids up to footprints of half a tile, then the tile-type
#: shares with in-tile moments, :func:`prefilter.glints.wang_ndf.type_moments`): point-light FLIP
#: 0.032 / 0.018 at mid / far (0.042 / 0.033 with the shares alone), one pyramid level fewer
#: than at 1, and far frames within 1.5x of ``glints``' (docs/glints-wang.md). ``code_bits``:
#: the cache file's CP factors (:func:`prefilter.glints.wang_store.save_tiles`): 8 (uint8
#: codes, the default), 16, or 0 (float32, format version 1); docs/glints-wang.md, "Storage
#: (version 2)".
WANG_SETTINGS = dict(tile=32, band=4.0, seed=0, ndf_res=256, support=1.0,
                     intrinsic_roughness=2 * DEFAULT_ROUGHNESS, stride0=None, wide_tiles=0.5,
                     uniform_tiles=8.0, rank=16, block=16, n_iter_max=50, bilinear=True,
                     code_bits=8)
_TILED: dict = {}
_BY_ID: dict = {}


#: Environment variable with a JSON object of :data:`WANG_SETTINGS` overrides (cheap bakes for
#: test runs: the default bake takes minutes whatever the exemplar's size).
SETTINGS_ENV = "PREFILTER_GLINTS_WANG_SETTINGS"


def wang_settings(settings: dict | None = None) -> dict:
    """:data:`WANG_SETTINGS` updated by ``$PREFILTER_GLINTS_WANG_SETTINGS`` (a JSON object),
    then by ``settings`` (unknown keys are an error)."""
    env = os.environ.get(SETTINGS_ENV)
    over = {}
    if env:
        try:
            over = json.loads(env)
        except ValueError:
            over = None
        if not isinstance(over, dict):
            raise PrefilterError(f"{SETTINGS_ENV}: expected a JSON object of settings, got "
                                 f"{env!r}")
    for what, d in ((SETTINGS_ENV, over), ("settings", settings or {})):
        extra = set(d) - set(WANG_SETTINGS)
        if extra:
            raise PrefilterError(f"{what}: expected keys among "
                                 f"{', '.join(sorted(WANG_SETTINGS))}, got "
                                 f"{', '.join(sorted(map(repr, extra)))}")
    st = {**WANG_SETTINGS, **over, **(settings or {})}
    # one type per key, so that equal settings give the same cache key (1 and 1.0)
    for k, v in st.items():
        ref = WANG_SETTINGS[k]
        if v is None and k == "stride0":
            continue
        if isinstance(ref, bool) or k == "bilinear":
            ok = isinstance(v, (bool, np.bool_))
        elif isinstance(ref, int) or k == "stride0":
            ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool)
        else:
            ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
        if not ok:
            raise PrefilterError(f"settings.{k}: expected a value of type "
                                 f"{type(ref).__name__}, got {v!r}")
        st[k] = type(ref)(v) if ref is not None else int(v)
    from prefilter.glints.wang_store import CODE_BITS

    if st["code_bits"] not in CODE_BITS:
        raise PrefilterError(f"settings.code_bits: expected one of {CODE_BITS}, got "
                             f"{st['code_bits']!r}")
    return st


def tile_size(tile: int, shape) -> int:
    """``tile`` capped at the exemplar's smaller side (rounded down to even, at least 4): the
    tiles of a small exemplar would repeat its patch (and cost the same bake)."""
    return max(4, min(int(tile), 2 * (min(shape) // 2)))


def cache_path(normal_map, settings: dict | None = None):
    """Path of the cached per-tile pyramids of an exemplar under ``settings`` (the file
    :func:`baked_tiles` reads or writes)."""
    nm = as_normal_map(normal_map)
    st = wang_settings(settings)
    st["tile"] = tile_size(st["tile"], nm.shape[:2])
    return _cache_path(nm, st)


def _cache_path(nm: np.ndarray, st: dict):
    """:func:`cache_path` of a validated exemplar ``nm`` and complete settings ``st`` (hashed
    as they are: validating ``nm`` again may change its last bits)."""
    from prefilter.glints.bake import cache_dir, settings_key
    from prefilter.glints.wang_store import VERSION

    # the store's format version in the key (and, by settings_key, the CP fit's): a file of
    # another layout, or fitted before a change to the fit, is never looked up
    key = settings_key(dict(st, store_version=VERSION))
    return cache_dir() / f"wang-{map_digest(nm)[:20]}-{key}.npz"


def baked_tiles(normal_map, settings: dict | None = None, *, progress: bool = False) -> TiledNDF:
    """The :class:`TiledNDF` of an exemplar: synthesised and baked once (disk cache), then kept
    in memory. Several processes share the cache: the first bakes under the lock, the others
    wait for it and load its file."""
    from prefilter.fileio import exclusive_lock
    from prefilter.glints.wang import synthesize
    from prefilter.glints.wang_ndf import bake_tiles
    from prefilter.glints.wang_store import load_tiles, save_tiles

    st = wang_settings(settings)
    # the renderer passes the same (cached) texture array every frame: skip hashing it again
    ident = (id(normal_map), json.dumps(st, sort_keys=True))
    hit = _BY_ID.get(ident)
    if hit is not None and hit[0] is normal_map:
        return hit[1]
    nm = as_normal_map(normal_map)
    st["tile"] = tile_size(st["tile"], nm.shape[:2])
    path = _cache_path(nm, st)
    if path not in _TILED:
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            with exclusive_lock(str(path) + ".lock"):
                if not path.exists():  # baked by the process that held the lock
                    wt = synthesize(nm, st["tile"], st["band"], rng=st["seed"])
                    rank = st["rank"] or None  # 0: uncompressed
                    wn = bake_tiles(wt, ndf_res=st["ndf_res"], support=st["support"],
                                    intrinsic_roughness=_bake_roughness(st),
                                    stride0=st["stride0"], wide_tiles=st["wide_tiles"],
                                    uniform_tiles=st["uniform_tiles"], rank=rank,
                                    block=st["block"], n_iter_max=st["n_iter_max"],
                                    seed=st["seed"], progress=progress)
                    save_tiles(wn, path, code_bits=st["code_bits"])
        _TILED[path] = load_tiles(path)
    if isinstance(normal_map, np.ndarray):
        _BY_ID[ident] = (normal_map, _TILED[path])
    return _TILED[path]


def _bake_roughness(st: dict) -> float:
    if not st["bilinear"]:
        return st["intrinsic_roughness"]
    from prefilter.glints.bake import bilinear_bake_roughness

    return bilinear_bake_roughness(st["intrinsic_roughness"], st["support"], st["ndf_res"])


def check_lights(scene, name: str = "glints-wang") -> None:
    """Point, directional, untextured quad and environment lights: a textured quad is a
    :class:`PrefilterError` naming the method (:func:`prefilter.glints.render.check_lights`)."""
    from prefilter.glints.render import check_lights as check

    check(scene, name)


#: Quad lights: light samples per shading sample, uniform on the light's area (no MIS: the
#: tiling's NDF sampler is per footprint in NumPy). 8: as many NDF evaluations as
#: ``glints-direct``'s MIS (``QUAD_MIS`` light and as many BRDF samples). At most
#: ``QUAD_MIS * (U_PAIR // 2)`` (:func:`quad_uniforms`).
QUAD_SAMPLES = 8


def quad_uniforms(u, qi: int, n: int = QUAD_SAMPLES) -> np.ndarray:
    """Light-sample uniforms ``(N, n, 2)`` of quad ``qi`` from the ``glints`` uniforms layout
    ``u (N, k)`` (:func:`prefilter.glints.render.random_dims`: ``QUAD_MIS`` pairs of ``U_PAIR``
    per quad): sample ``j`` reads pair ``j % QUAD_MIS``'s uniforms ``2 (j // QUAD_MIS)`` and the
    next, so the first ``QUAD_MIS`` are ``glints-direct``'s light samples."""
    from prefilter.glints.render import QUAD_MIS, U_PAIR, uniform_columns

    if not 0 < n <= QUAD_MIS * (U_PAIR // 2):
        raise PrefilterError(f"n: expected 1 to {QUAD_MIS * (U_PAIR // 2)} light samples, "
                             f"got {n}")
    u = np.asarray(u, dtype=np.float64)
    cols = uniform_columns(qi + 1, "quad", qi)
    if u.ndim != 2 or u.shape[1] < cols.stop:
        raise PrefilterError(f"u: expected uniforms of shape (N, >= {cols.stop}), got {u.shape}")
    blk = u[:, cols].reshape(len(u), QUAD_MIS, U_PAIR)
    j = np.arange(n)
    o = 2 * (j // QUAD_MIS)
    return np.stack([blk[:, j % QUAD_MIS, o], blk[:, j % QUAD_MIS, o + 1]], -1)


def _quad_samples(ql, position, frame, uq):
    """Light samples of quad ``ql``: local unit directions ``(n, N, 3)`` and the weights
    ``L / (n pdf)`` ``(n, N, 3)`` (0 where the sample is not seen from the front) of the
    light-sampling estimator; ``uq (N, n, 2)`` uniforms, ``frame`` ``(t, b, n)`` world."""
    from prefilter.render.lights import quad_light_sample
    from prefilter.sphere.sampling import to_local

    N, n = uq.shape[:2]
    pos = np.tile(position, (n, 1))
    w, pdf = quad_light_sample(ql, pos, uq.transpose(1, 0, 2).reshape(n * N, 2))
    wi = to_local(w, *(np.tile(x, (n, 1)) for x in frame))
    wi /= np.maximum(np.linalg.norm(wi, axis=-1, keepdims=True), 1e-300)
    ok = pdf > 0
    wgt = np.where(ok, 1.0 / (n * np.where(ok, pdf, 1.0)), 0.0)
    L = np.asarray(ql.radiance, dtype=np.float64)
    return wi.reshape(n, N, 3), wgt.reshape(n, N, 1) * L


def _environment_samples(light, frame, u, wn, center, sigma_p, wo, index, point_roughness, *,
                         prefilter: bool = True):
    """SG light samples of an environment light (those of
    :func:`prefilter.glints.envlight.shade_sg` with ``u``): local directions ``(n, N, 3)``, the
    weights ``L(wi) / (n pdf)`` ``(n, N, 3)`` and the prefiltered NDF ``(n, N)``: the range mean
    of the footprint NDF over ``h_xy +- theta_eps / 2`` of the sample's lobe
    (:data:`prefilter.glints.render.ENV_EPS`; glints paper sec. 5.4, as ``glints``), NaN where
    the point NDF is used (below ``wn.min_sigma``, as ``glints`` below its finest level, and
    everywhere without ``prefilter``) or the sample does not reflect; ``u (N, 3 n)``."""
    from prefilter.glints.envlight import (_lobe_probabilities, as_lobes, eps_support,
                                           sg_energy, sg_light_samples)
    from prefilter.glints.render import ENV_EPS, environment_lobes

    mu, lam, p = as_lobes(*environment_lobes(light, frame))
    wi, wgt = sg_light_samples(mu, lam, p, u)
    n = wi.shape[0]
    D = np.full(wi.shape[:2], np.nan)
    big = sigma_p >= wn.min_sigma
    if not (prefilter and np.any(big) and wn.block):
        return wi, wgt, D
    # the lobe each sample was drawn from (envlight._sample_sg's choice)
    cum = np.cumsum(_lobe_probabilities(mu.mean(axis=1) * sg_energy(lam)))
    lobe = np.minimum(np.searchsorted(cum, u[:, 0:3 * n:3], side="right"), len(cum) - 1)
    half_eps = np.maximum(0.5 * eps_support(mu, lam, ENV_EPS)[lobe], 1e-6)  # (N, n)
    h = wi + wo[None]
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    ok = (wi[..., 2] > 0) & (h[..., 2] > 0) & (wo[None, :, 2] > 0)  # (n, N)
    hs = h[..., :2].transpose(1, 0, 2)[big]  # (N_big, n, 2)
    r = half_eps[big][..., None]
    mean, _ = ranges(wn, center[big], sigma_p[big], hs - r, hs + r, active=ok.T[big],
                     index=index, point_roughness=point_roughness)
    D[:, big] = np.where(ok[:, big], mean.T, 0.0)
    return wi, wgt, D


def quad_range_wang(wn: TiledNDF, center, sigma_p, wo, corners, radiance, f0, *, index=None,
                    point_roughness=None):
    """Specular radiance ``(N, 3)`` of a quad light by range queries over its half-vector
    region (:func:`prefilter.glints.render.quad_range`'s patches, ``QUAD_SUB^2`` then
    ``(2 QUAD_SUB)^2`` for larger lights, each rectangle's mean from
    :func:`prefilter.glints.wang_range.ndf_ranges`: across tile borders) and ``done (N,)``:
    where it applies (the patch conditions of :func:`prefilter.glints.render.quad_patches`,
    footprints at or above ``wn.min_sigma``, compressed pyramids); 0 elsewhere (light samples
    there)."""
    from prefilter.glints.render import QUAD_SUB, quad_patches

    N = len(sigma_p)
    out = np.zeros((N, 3))
    done = np.zeros(N, bool)
    if not wn.block:
        return out, done
    for n_sub in (QUAD_SUB, 2 * QUAD_SUB):
        cand = np.flatnonzero(~done & (sigma_p >= wn.min_sigma))
        if not cand.size:
            break
        ok, lo, hi, (k, ja) = quad_patches(wo[cand], corners[cand], f0, n_sub)
        if not np.any(ok):
            continue
        sel = cand[ok]
        mean, _ = ranges(wn, center[sel], sigma_p[sel], lo, hi, index=index,
                         point_roughness=point_roughness)
        out[sel] = (k * (ja * mean)[..., None]).sum(axis=1) * np.asarray(radiance, np.float64)
        done[sel] = True
    return out, done


def ranges(wn, center, sigma_p, lo, hi, **kw):
    """:func:`prefilter.glints.wang_range.ndf_ranges` (imported on first use)."""
    from prefilter.glints.wang_range import ndf_ranges

    return ndf_ranges(wn, np.ascontiguousarray(center), np.ascontiguousarray(sigma_p), lo, hi,
                      **kw)


def shade_wang(scene, g, *, spp: int = 1, u=None, index=None, settings: dict | None = None,
               progress: bool = False, ranges: bool = True, direct: bool = False) -> np.ndarray:
    """Radiance ``(N, 3)`` of hit samples ``g`` under the scene's lights.

    Point and directional lights: the BRDF at the light direction. Untextured quads: light
    sampling (:data:`QUAD_SAMPLES` per sample, :func:`quad_uniforms`), diffuse by Lambert's
    polygon formula. Environment lights: the SG light samples of ``glints-direct``
    (``ENV_SAMPLES``, :func:`prefilter.glints.render.environment_radiance` unprefiltered).
    ``D`` of every sample of every light of an object: one :func:`ndf_points` call.
    ``u (N, random_dims(scene))``: the ``glints`` uniforms layout (needed with quad or
    environment lights). ``index``: an explicit ``(ny, nx)`` tile index map (periodic, tile
    ``(0, 0)`` at texel ``(0, 0)``) instead of the hashing; ``settings``: overrides of
    :data:`WANG_SETTINGS`. ``ranges`` False: no range queries (quad lights by light samples
    only, the environment's NDF at the samples' half vectors without the lobe prefilter: then
    the same estimator as ``glints-direct`` for environments); ``direct``: also the direct P-NDF
    of the tiling at every footprint (:func:`prefilter.glints.wang_ndf.ndf_points`' ``direct``):
    ``glints-direct``'s NDF on the tiling, the reference of the regimes, with these estimators.
    """
    from prefilter.glints.brdf import brdf_cos_from_ndf, half
    from prefilter.glints.render import footprints, random_dims, uniform_columns
    from prefilter.ltc import clamped_cosine_integral
    from prefilter.render.shading import point_incoming, shading_frames
    from prefilter.sphere.sampling import to_local

    check_lights(scene)
    st = wang_settings(settings)
    prefiltered = ranges and not direct  # quad range queries, the environment's lobe prefilter
    lights = scene.light_set()
    env = [lt for lt in scene.lights if lt.type == "environment"]
    nq = len(lights.quads)
    t, b, n, wo = shading_frames(g)
    incoming = point_incoming(lights, g.position)
    out = np.zeros((len(wo), 3))
    if not (incoming or nq or env):
        return out
    k_u = random_dims(scene)
    if nq or env:
        if u is None:
            raise PrefilterError("u: expected uniforms for the quad and environment lights' "
                                 "samples, got None")
        u = np.asarray(u, dtype=np.float64)
        if u.ndim != 2 or u.shape[0] != len(wo) or u.shape[1] < k_u:
            raise PrefilterError(f"u: expected uniforms of shape ({len(wo)}, >= {k_u}), got "
                                 f"{u.shape}")
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        if mat.normal_map is None:
            raise PrefilterError(f"objects[{int(k)}].material.normal_map: method 'glints-wang' "
                                 "expected a normal map (the exemplar), got none")
        nm = mat.normal_map.load()
        wn = baked_tiles(nm, settings, progress=progress)
        c, sp = footprints(g.select(m), nm.shape[:2], spp)
        frame = (t[m], b[m], n[m])
        base = np.asarray(mat.base_color, dtype=np.float64)
        # every light sample of the object: directions wi (S, N_k, 3) in the local frame,
        # weights (S, N_k, 3) (irradiance, or radiance over pdf and sample count), and whether
        # its Lambert term comes from the sample (quads: the exact polygon integral instead)
        wis, wgts, lamb, pre = [], [], [], []
        f0 = np.asarray(mat.f0, dtype=np.float64)
        for w, e in incoming:
            wi = to_local(w[m], *frame)
            wis.append(wi / np.linalg.norm(wi, axis=-1, keepdims=True))
            wgts.append(e[m])
            lamb.append(True)
            pre.append(None)
        for qi, ql in enumerate(lights.quads):
            corners = np.stack([to_local(v - g.position[m], *frame) for v in ql.vertices], 1)
            if np.any(base > 0):
                out[m] += base * ql.radiance * clamped_cosine_integral(corners)[:, None]
            if prefiltered:
                val, done = quad_range_wang(wn, c, sp, wo[m], corners, ql.radiance, f0,
                                            index=index,
                                            point_roughness=st["intrinsic_roughness"])
                out[m] += val
            else:
                done = np.zeros(len(sp), bool)
            wi, wgt = _quad_samples(ql, g.position[m], frame, quad_uniforms(u[m], qi))
            wgt[:, done] = 0.0  # the range path's samples: not queried, not added
            wis += list(wi)
            wgts += list(wgt)
            lamb += [False] * len(wi)
            pre += [np.where(done, 0.0, np.nan)] * len(wi)
        for j, light in enumerate(env):
            cols = uniform_columns(nq, "environment", j)
            wi, wgt, D = _environment_samples(light, frame, u[m][:, cols], wn, c, sp, wo[m],
                                              index, st["intrinsic_roughness"],
                                              prefilter=prefiltered)
            wis += list(wi)
            wgts += list(wgt)
            lamb += [True] * len(wi)
            pre += list(D)
        wi = np.stack(wis)
        wok = np.broadcast_to(wo[m], wi.shape)
        h = half(wok, wi)
        # only the samples that can reflect are queried (env: ~half below the horizon), and
        # not those whose NDF a range query gave (prefiltered environment, quad ranges)
        known = np.stack([np.full(len(c), np.nan) if d is None else d for d in pre])
        act = (wi[..., 2] > 0) & (h[..., 2] > 0) & (wok[..., 2] > 0) & np.isnan(known)
        D = np.where(np.isnan(known), 0.0, known)
        if np.any(act):
            # footprint-major (each pixel's samples together: ndf_points forms a footprint's
            # elements once for all of them)
            at = act.T
            D.T[at] = ndf_points(wn, np.broadcast_to(c[:, None], (len(c), len(wi), 2))[at],
                                 np.broadcast_to(sp[:, None], at.shape)[at],
                                 h.transpose(1, 0, 2)[at][:, :2], index=index,
                                 bilinear=st["bilinear"],
                                 point_roughness=st["intrinsic_roughness"], direct=direct)
        spec = brdf_cos_from_ndf(wok, wi, h, D, f0)
        diff = base / np.pi * np.maximum(wi[..., 2], 0.0)[..., None]
        for j in range(len(wi)):
            out[m] += (spec[j] + diff[j] if lamb[j] else spec[j]) * wgts[j]
    return out


def render_wang(scene, settings, *, index=None, wang: dict | None = None, ranges: bool = True,
                direct: bool = False) -> np.ndarray:
    """Linear radiance ``(H, W, 3)`` float32 of ``scene`` by ``glints-wang`` (module docstring).

    ``index``: explicit periodic tile index map (see :func:`shade_wang`); ``wang``: overrides
    of :data:`WANG_SETTINGS`; ``ranges``, ``direct``: the estimators and the reference NDF of
    :func:`shade_wang`. The uniforms per sample are those of ``glints`` /
    ``glints-direct`` (:func:`prefilter.glints.render.random_dims`, same rows and seed): the
    same light samples. The registered method is this with the defaults."""
    from prefilter.glints.render import random_dims
    from prefilter.render.driver import render_samples

    check_lights(scene)
    wang_settings(wang)
    spp = settings.spp
    img = render_samples(scene, settings,
                         lambda g, u: shade_wang(scene, g, spp=spp, u=u, index=index,
                                                 settings=wang, progress=settings.progress,
                                                 ranges=ranges, direct=direct),
                         random_dims=random_dims(scene), stratified=spp > 1, desc="glints-wang")
    return img.astype(np.float32)


def render_glints_wang(scene, settings) -> np.ndarray:
    """The ``glints-wang`` method: glint BRDF with the footprint NDF of the implicit Wang
    tiling of the material's normal map (point, directional, untextured quad and environment
    lights). Variant ``estimator``: ``prefiltered`` (the default: range queries for quads, the
    environment's lobe prefilter), ``samples`` (``ranges=False``), ``direct`` (``direct=True``:
    the direct P-NDF of the tiling at every footprint, the reference; its cost grows with the
    footprint)."""
    est = settings.param("estimator", "prefiltered")
    return render_wang(scene, settings, ranges=est == "prefiltered", direct=est == "direct")
