"""Render methods ``glints-wave`` and ``glints-wave-direct``: glints under wave optics.

The microstructure is a heightfield named by the scene field ``extras.glints_wave``::

    "extras": {"glints_wave": {"heightfield": "procedural:noise:128:0", "texel_size": 2.5e-7}}

(``heightfield``: ``procedural:KIND[:SIZE[:SEED]]`` or an image / ``.npy`` of heights in metres;
``texel_size``: metres per texel, required for files, default the procedural one's). Every object
is shaded with its RGB glint lobe over the pixel footprint (footprints as the geometric methods',
:func:`prefilter.glints.render.footprints`, in texels of the heightfield) plus Lambert
``base_color``; ``f0`` is the material's. Point and directional lights, untextured quads (light
sampling, :func:`quad_light_rgb`; diffuse by Lambert's polygon formula) and environment maps
(light sampling, :func:`environment_rgb`): both methods draw the same light samples, so they
compare the NDF at the same half vectors.

* ``glints-wave``: the compressed RGB pyramid (:mod:`prefilter.glints.wave.bake`, baked on first
  use into the glints cache, keyed by the heightfield's digest and the settings), point queries
  with the geometric method's Gaussian resampling and bilinear NDF lookup
  (:mod:`prefilter.glints.wave.lobe`).
* ``glints-wave-direct``: the model without pyramid or compression
  (:class:`prefilter.glints.wave.direct.DirectWave`: the coherence areas' exact weights), its
  level-0 images cached on disk.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.fileio import atomic_path, bake_lock
from prefilter.glints.bake import cache_dir
from prefilter.glints.brdf import brdf_cos_from_ndf, half
from prefilter.glints.render import footprints
from prefilter.glints.wave.bake import (WAVE_SETTINGS, WAVE_VERSION, as_heightfield_spec,
                                        bake_wave, cache_path, channel_paths, load_wave,
                                        wave_settings)
from prefilter.glints.wave.direct import DirectWave
from prefilter.glints.wave.lobe import point_rgb
from prefilter.render.shading import point_incoming, shading_frames
from prefilter.sphere.sampling import to_local

_MAPS: dict = {}
_DIRECT: dict = {}
_KEYS = ("heightfield", "texel_size")


def scene_heightfield(scene):
    """The heightfield of ``scene.extras.glints_wave`` (see the module docstring)."""
    spec = (getattr(scene, "extras", None) or {}).get("glints_wave")
    if not isinstance(spec, dict) or "heightfield" not in spec:
        raise PrefilterError("extras.glints_wave: the glints-wave methods expected an object "
                             "with 'heightfield' (and 'texel_size' for files), got "
                             f"{spec!r}")
    extra = sorted(set(spec) - set(_KEYS))
    if extra:
        raise PrefilterError(f"extras.glints_wave: unknown field {extra[0]!r} (expected "
                             f"{', '.join(_KEYS)})")
    path = str(spec["heightfield"])
    if not path.startswith("procedural:") and not Path(path).is_absolute():
        path = str(Path(getattr(scene, "base_dir", ".") or ".") / path)
    return as_heightfield_spec(path, spec.get("texel_size"))


def wave_map(hf, settings: dict | None = None, progress: bool = False):
    """The baked :class:`~prefilter.glints.wave.bake.WaveMap` of ``hf`` (glints cache, at
    :func:`~prefilter.glints.wave.bake.cache_path`; ``prefilter bake glints-wave`` writes the
    same file)."""
    st = wave_settings(hf.shape, settings)
    out = cache_path(hf, st)
    key = str(out)
    if key not in _MAPS:
        out.parent.mkdir(parents=True, exist_ok=True)
        if not all(p.exists() for p in channel_paths(out)):
            bake_wave(hf, out, progress=progress, **st)
        _MAPS[key] = load_wave(out)
    return _MAPS[key]


def direct_model(hf, settings: dict | None = None) -> DirectWave:
    """The :class:`DirectWave` of ``hf`` (level-0 images cached in the glints cache)."""
    st = dict(WAVE_SETTINGS, **(settings or {}))
    args = dict(ndf_res=st["ndf_res"], support=st["support"], stride0=st["stride0"])
    key = json.dumps(dict(args, heights=hf.digest, version=WAVE_VERSION), sort_keys=True)
    if key not in _DIRECT:
        import hashlib

        path = cache_dir() / f"wave-direct-{hashlib.sha1(key.encode()).hexdigest()[:16]}.npy"
        path.parent.mkdir(parents=True, exist_ok=True)
        with bake_lock(path, wait=True):
            if path.exists():
                dw = DirectWave(hf, images=np.load(path), **args)
            else:
                dw = DirectWave(hf, **args)
                with atomic_path(path, suffix=".npy") as tmp:
                    np.save(tmp, dw.images)
        _DIRECT[key] = dw
    return _DIRECT[key]


def brdf_cos_from_rgb(wo, wi, h, D, f0) -> np.ndarray:
    """``F G D_c / (4 wo_z)`` per channel ``(N, 3)`` from RGB NDF values ``D (N, 3)``."""
    f0 = np.broadcast_to(np.asarray(f0, np.float64), (3,))
    return np.stack([brdf_cos_from_ndf(wo, wi, h, D[:, c], f0[c:c + 1])[:, 0]
                     for c in range(3)], axis=-1)


#: Quad lights: light samples (uniform on the quad's area) per shading sample and quad; each
#: takes two uniforms.
QUAD_SAMPLES = 8


def quad_light_rgb(ndf, center, sigma_p, wo, position, frame, light, f0, u) -> np.ndarray:
    """Specular radiance ``(N, 3)`` of quad ``light`` by light sampling: the mean over the
    samples ``j`` of ``f(wo, wi_j) cos L / p(wi_j)``, ``wi_j`` uniform on the quad's area
    (:func:`prefilter.render.lights.quad_light_sample`, ``p`` its solid-angle density), the RGB
    NDF ``ndf(center, sigma_p, s)`` at the samples' half vectors (one call for all of them).

    Parameters
    ----------
    wo : (N, 3) local view directions; position : (N, 3) world shading points; frame :
    (t, b, n) each (N, 3); u : (N, 2 K) uniforms in ``[0, 1)`` (K samples).
    """
    from prefilter.render.lights import quad_light_sample

    N, K = len(wo), u.shape[1] // 2
    if N == 0 or K == 0:
        return np.zeros((N, 3))
    # the K samples of every shading sample at once: rows sample-major (K N)
    uk = u[:, :2 * K].reshape(N, K, 2).transpose(1, 0, 2).reshape(K * N, 2)
    w, pdf = quad_light_sample(light, np.tile(position, (K, 1)), uk)
    radiance = np.asarray(light.radiance, dtype=np.float64)
    return _light_samples_rgb(ndf, center, sigma_p, wo, frame, w, pdf, radiance, f0, 0.0)


def _light_samples_rgb(ndf, center, sigma_p, wo, frame, w, pdf, L, f0, base) -> np.ndarray:
    """``(N, 3)``: the mean over ``K`` light samples of ``(f(wo, wi) + base / pi wi.z) L / p``.

    ``w (K N, 3)`` world directions, sample-major, with densities ``pdf (K N,)`` and radiance
    ``L`` (``(K N, 3)`` or ``(3,)``); samples below the horizon or of zero density count 0.
    """
    N = len(wo)
    K = len(w) // N
    t, b, n = (np.tile(x, (K, 1)) for x in frame)
    wi = to_local(w, t, b, n)
    wi /= np.maximum(np.linalg.norm(wi, axis=-1, keepdims=True), 1e-300)
    woK = np.tile(wo, (K, 1))
    ok = (pdf > 0) & (wi[:, 2] > 0)
    wi = np.where(ok[:, None], wi, np.array([0.0, 0.0, 1.0]))
    h = half(woK, wi)
    D = ndf(np.tile(center, (K, 1)), np.tile(sigma_p, K), h[:, :2])
    f = brdf_cos_from_rgb(woK, wi, h, D, f0) + base / np.pi * wi[:, 2:3]
    val = np.where(ok[:, None], f * L / np.where(ok, pdf, 1.0)[:, None], 0.0)
    return val.reshape(K, N, 3).mean(axis=0)


#: Environment lights: directions drawn from the map (texels by luminance times solid angle,
#: :class:`prefilter.render.pathtrace.EnvironmentSampler`) per shading sample and environment;
#: each takes three uniforms.
ENV_SAMPLES = 16
_ENV: dict = {}


def environment_rgb(ndf, center, sigma_p, wo, frame, sampler, f0, base, u) -> np.ndarray:
    """Radiance ``(N, 3)`` of an environment light by light sampling: the mean over the samples
    ``j`` of ``(f(wo, wi_j) + base / pi wi_j.z) L(wi_j) / p(wi_j)`` with ``wi_j`` from
    ``sampler`` (an :class:`~prefilter.render.pathtrace.EnvironmentSampler`), the RGB NDF
    ``ndf(center, sigma_p, s)`` at the samples' half vectors (one call); no occlusion.

    Parameters
    ----------
    wo : (N, 3) local view directions; frame : (t, b, n) each (N, 3); u : (N, 3 K) uniforms in
    ``[0, 1)`` (K samples).
    """
    N, K = len(wo), u.shape[1] // 3
    if N == 0 or K == 0:
        return np.zeros((N, 3))
    uk = u[:, :3 * K].reshape(N, K, 3).transpose(1, 0, 2).reshape(K * N, 3)
    w, pdf = sampler.sample(uk)
    return _light_samples_rgb(ndf, center, sigma_p, wo, frame, w, pdf, sampler.eval(w), f0, base)


def _environments(scene) -> list:
    """The :class:`~prefilter.render.pathtrace.EnvironmentSampler` of each environment light of
    ``scene`` (cached per image and scale)."""
    from prefilter.render.pathtrace import EnvironmentSampler

    out = []
    for lt in scene.lights:
        if lt.type == "environment":
            key = (lt.image.cache_key(), float(lt.scale))
            if key not in _ENV:
                _ENV[key] = EnvironmentSampler.of(lt)
            out.append(_ENV[key])
    return out


def n_uniforms(scene) -> int:
    """Uniforms per shading sample of the glints-wave methods: ``2 QUAD_SAMPLES`` per quad
    light, then ``3 ENV_SAMPLES`` per environment light."""
    n_env = sum(lt.type == "environment" for lt in scene.lights)
    return 2 * QUAD_SAMPLES * len(scene.light_set().quads) + 3 * ENV_SAMPLES * n_env


def shade_wave(scene, g, *, mode: str, spp: int = 1, u=None,
               progress: bool = False) -> np.ndarray:
    """Radiance ``(N, 3)`` of hit samples ``g`` under the scene's point, directional, quad and
    environment lights; ``mode``: ``"compressed"`` or ``"direct"``; ``u (N, n_uniforms(scene))``:
    the quads' then the environments' uniforms."""
    from prefilter.ltc import clamped_cosine_integral

    hf = scene_heightfield(scene)
    if mode == "compressed":
        wm = wave_map(hf, progress=progress)

        def ndf(c, sp, s):
            return point_rgb(wm, c, sp, s)
    else:
        dw = direct_model(hf)
        ndf = dw.point
    lights = scene.light_set()
    envs = _environments(scene)
    k_u = n_uniforms(scene)
    if k_u and (u is None or np.shape(u)[-1] < k_u):
        raise PrefilterError(f"u: expected {k_u} uniforms per sample for the scene's quad and "
                             f"environment lights, got {None if u is None else np.shape(u)}")
    q0 = 2 * QUAD_SAMPLES * len(lights.quads)
    t, b, n, wo = shading_frames(g)
    c, sp = footprints(g, hf.shape, spp)
    out = np.zeros((len(wo), 3))
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        base = np.asarray(mat.base_color, dtype=np.float64)
        f0 = np.broadcast_to(np.asarray(mat.f0, dtype=np.float64), (3,))
        for w, e in point_incoming(lights, g.position[m]):
            wi = to_local(w, t[m], b[m], n[m])
            wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
            h = half(wo[m], wi)
            D = ndf(c[m], sp[m], h[:, :2])
            spec = brdf_cos_from_rgb(wo[m], wi, h, D, f0)
            out[m] += (spec + base / np.pi * np.maximum(wi[:, 2], 0.0)[:, None]) * e
        frame = (t[m], b[m], n[m])
        for qi, ql in enumerate(lights.quads):
            if np.any(base > 0):
                corners = np.stack([to_local(v - g.position[m], *frame) for v in ql.vertices], 1)
                out[m] += base * ql.radiance * clamped_cosine_integral(corners)[:, None]
            uq = u[m][:, 2 * QUAD_SAMPLES * qi:2 * QUAD_SAMPLES * (qi + 1)]
            out[m] += quad_light_rgb(ndf, c[m], sp[m], wo[m], g.position[m], frame, ql, f0, uq)
        for j, env in enumerate(envs):
            ue = u[m][:, q0 + 3 * ENV_SAMPLES * j:q0 + 3 * ENV_SAMPLES * (j + 1)]
            out[m] += environment_rgb(ndf, c[m], sp[m], wo[m], frame, env, f0, base, ue)
    return out


def _check_lights(scene, name):
    for i, light in enumerate(scene.lights):
        if light.type not in ("point", "directional", "quad", "environment") \
                or getattr(light, "texture", None) is not None:
            kind = "a textured quad" if light.type == "quad" else repr(light.type)
            raise PrefilterError(f"lights[{i}]: method {name!r} expected point, directional, "
                                 f"untextured quad or environment lights, got {kind}")


def _render(scene, settings, mode, name):
    from prefilter.render.driver import render_samples

    _check_lights(scene, name)
    scene_heightfield(scene)  # a bad heightfield fails before any work
    spp = settings.spp
    k = n_uniforms(scene)
    return render_samples(scene, settings,
                          lambda g, u: shade_wave(scene, g, mode=mode, spp=spp, u=u,
                                                  progress=settings.progress),
                          random_dims=k, stratified=spp > 1, desc=name)


def render_glints_wave(scene, settings) -> np.ndarray:
    """The ``glints-wave`` method: compressed RGB wave-optics footprint NDF (point queries)."""
    return _render(scene, settings, "compressed", "glints-wave")


def render_glints_wave_direct(scene, settings) -> np.ndarray:
    """The ``glints-wave-direct`` method: the wave-optics footprint NDF from the uncompressed
    coherence-area images with exact weights."""
    return _render(scene, settings, "direct", "glints-wave-direct")
