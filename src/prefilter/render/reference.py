"""Ground truth: supersampled pixel footprints and Monte Carlo integration over the lights.

Per pixel, sub-pixel positions are traced with the G-buffer code and shaded with full-resolution
textures (level 0, bilinear). Each quad light is integrated by the MIS estimator of
:mod:`prefilter.render.estimator` (one light sample, uniform in solid angle on rectangles and on
the area of other quads, and one BRDF sample, GGX visible normals or cosine, per pair; balance
heuristic, Veach 1997, eq. 9.13), using the true GGX BRDF with Schlick Fresnel
(:func:`prefilter.render.shading.brdf_cos`). By default the isotropic GGX LTC table's fit of the
specular lobe is a control variate on untextured quads: its exact polygon integral is added and
its value subtracted from every sample (:func:`prefilter.render.estimator.ltc_control`), which
keeps the estimate unbiased whatever the fit and removes most of the noise of light edges
crossing glossy lobes (``--param control=none``: plain MIS). ``spp`` is the number of light/BRDF
sample pairs per pixel; they are shaded in groups of :func:`pairs_per_position` at
``spp / pairs`` sub-pixel positions (one pair per position with the control variate, whose
pairs' error is small; :data:`PAIRS_PER_POSITION` without it, as tracing and texture reads cost
more than a pair). All uniforms (positions,
and each light's light and BRDF samples) are per-pixel Owen-scrambled Sobol points
(:func:`prefilter.render.estimator.owen_sobol`), so the estimator is unbiased and its error falls
faster than ``O(spp^-1/2)``; ``benchmarks/bench_reference_noise.py`` measures it.

Textured quad lights (:class:`prefilter.render.lighttex.TexturedQuad`) are sampled the same way;
each sample's radiance is multiplied by the light texture at the sample's point on the light,
read at level 0 (bilinear, texel centres at ``(i + 0.5) / size``) with the texture coordinates of
:func:`prefilter.render.lighttex.texture_uv` (``p = v0 + u (v1 - v0) + v (v3 - v0)``, ``u`` along
columns): the same convention as the ``ltc`` method's prefiltered lookups. The densities do not
depend on the texture, so the estimator stays unbiased (only its variance grows with the
texture's contrast).

Scenes lit by untextured quad lights only are rendered by one fused Numba kernel per row chunk
(:func:`reference_samples_kernel`: camera ray, hit, level-0 texture reads, shading frame, then the
MIS pairs drawn and shaded in place by the same jitted helpers as the array kernel); others run the
NumPy stages, which give the same image to rounding.

Images depend only on ``seed`` and ``spp`` (scrambles are keyed by the pixel), not on the chunk size
or thread count.
"""

from __future__ import annotations

import functools

import numpy as np

from prefilter.jit import njit_parallel, prange
from prefilter.render.camera import camera_params, gbuffer_at
from prefilter.render.driver import render_positions, surface_attributes, with_settings
from prefilter.microfacet.ggx import ggx_lambda_jit
from prefilter.render.estimator import (
    HEURISTICS,
    NO_CONTROL,
    MaterialLobe,
    control_arrays,
    ltc_control,
    ltc_control_integral,
    material_mis,
    material_mis_pair,
    mis_quad,
    owen_sobol,
    owen_sobol_coord,
    owen_sobol_index,
    owen_sobol_pixel,
    sobol_base,
    sobol_key,
    specular_probability_jit,
)
from prefilter.render.kernels import (
    gscratch,
    level0_read,
    pack_materials,
    pack_objects,
    surface_sample,
)
from prefilter.render.lights import (
    RECT_WIDTH,
    LightSet,
    QuadLight,
    quad_constants,
    quad_rectangle,
    quad_setup_jit,
)
from prefilter.render.shading import VIEW_Z_MIN, local_view, shade_delta_lights

#: Light/BRDF sample pairs shaded per traced sub-pixel position at high sample counts without
#: the control variate (:func:`pairs_per_position`; with it, one).
PAIRS_PER_POSITION = 4


def light_emission(light, points) -> np.ndarray:
    """Texture factor ``(N, 3)`` of a quad light at ``points (N, 3)`` on it: the level-0 bilinear
    texel of a :class:`~prefilter.render.lighttex.TexturedQuad` at its
    :func:`~prefilter.render.lighttex.texture_uv` (clamped to the light), ones for an untextured
    :class:`QuadLight`. A one-channel texture scales all three channels."""
    n = len(points)
    tex = getattr(light, "texture", None)
    if tex is None:
        return np.ones((n, 3))
    from prefilter.render.lighttex import texture_uv

    t = tex.lookup(texture_uv(light.vertices, points), 0.0)  # sigma 0: level 0, bilinear
    return t if t.shape[1] == 3 else np.repeat(t[:, :1], 3, axis=1)


def _geometry(light) -> QuadLight:
    """The untextured quad of ``light`` (its sampling densities ignore the texture)."""
    return light if isinstance(light, QuadLight) else QuadLight(light.vertices, light.radiance)


def estimate_quad(light, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, u, *,
                  heuristic: str = "balance") -> np.ndarray:
    """MIS estimate ``(N, 3)`` of the radiance reflected from one quad light, one pair of samples
    per point (:func:`prefilter.render.estimator.mis_quad` of the material lobe, NumPy).

    ``light``: a :class:`QuadLight` or a textured quad (its radiance times
    :func:`light_emission` at each sample's point on the light). ``u (N, 4)``: 2 uniforms for the
    light sample, 2 for the BRDF sample.
    """
    geo = _geometry(light)
    lobe = MaterialLobe.for_view(wo, alpha_x, alpha_y, base_color, f0)
    terms, points = mis_quad(lobe, geo, position, ts, bs, ns, wo, u, heuristic=heuristic)
    return _combine(light, terms[:, None], points[:, None])


def estimate_quad_fast(light, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, u, *,
                       heuristic: str = "balance", control=None) -> np.ndarray:
    """:func:`estimate_quad` by the Numba kernel, averaged over ``K`` pairs when
    ``u (N, K, 4)`` (``u (N, 4)``: one pair, the same numbers as :func:`estimate_quad` to
    rounding); the light texture, if any, is read afterwards at the samples' points.
    ``control``: the LTC control variate's table (untextured lights only), or ``None``."""
    u = np.asarray(u, dtype=np.float64)
    if u.ndim == 2:
        u = u[:, None]
    textured = getattr(light, "texture", None) is not None
    total, terms, points = material_mis(_geometry(light), position, ts, bs, ns, wo, alpha_x,
                                        alpha_y, base_color, f0, u, heuristic=heuristic,
                                        keep=textured, control=None if textured else control)
    if textured:
        return _combine(light, terms, points)
    return total * (light.radiance / u.shape[1])


def _combine(light, terms, points) -> np.ndarray:
    """Radiance ``(N, 3)`` from the MIS terms ``(N, K, 2, 3)`` of ``K`` pairs and their points on
    the light ``(N, K, 2, 3)``: the mean over pairs, times the light's radiance and texture."""
    n, k = terms.shape[:2]
    if getattr(light, "texture", None) is not None:
        terms = terms * light_emission(light, points.reshape(-1, 3)).reshape(terms.shape)
    return terms.sum(axis=(1, 2)) * (light.radiance / k)


def shade_reference(position, frame_t, frame_b, frame_n, view, alpha_x, alpha_y, base_color, f0,
                    lights: LightSet, u, *, textured=(), kernel: bool = True,
                    heuristic: str = "balance", control=None) -> np.ndarray:
    """Monte Carlo radiance ``(N, 3)`` at shading points, ``K`` MIS sample pairs per quad light.

    Parameters
    ----------
    position, frame_t, frame_b, frame_n, view : (N, 3)
        Shading points, their (normal-mapped) shading frames and unit directions to the eye.
    alpha_x, alpha_y : (N,)
        GGX roughness along ``frame_t`` and ``frame_b``.
    base_color, f0 : (N, 3)
    lights : LightSet
    u : (N, Q + T, 4) or (N, Q + T, K, 4)
        Uniform random numbers, ``Q = len(lights.quads)`` then ``T = len(textured)`` (one pair
        per light, or ``K``).
    textured : sequence of TexturedQuad
        Textured quad lights (:func:`prefilter.render.lighttex.split_lights`).
    kernel : bool
        Use the Numba kernel (default) or the NumPy estimator (same numbers to rounding; one
        pair only).
    heuristic : {"balance", "power"}
    control : tuple of arrays or None
        The LTC table of the control variate (:func:`prefilter.render.estimator.control_arrays`)
        for the untextured quads, with ``kernel`` only; ``None``: plain MIS.

    Point and directional lights are evaluated exactly (no sampling).
    """
    position = np.asarray(position, dtype=np.float64)
    ts, bs, ns = (np.asarray(a, dtype=np.float64) for a in (frame_t, frame_b, frame_n))
    alpha_x = np.asarray(alpha_x, dtype=np.float64)
    alpha_y = np.asarray(alpha_y, dtype=np.float64)
    base_color = np.asarray(base_color, dtype=np.float64)
    f0 = np.asarray(f0, dtype=np.float64)
    wo = local_view(view, ts, bs, ns)
    out = shade_delta_lights(position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, lights)
    for q, ql in enumerate(tuple(lights.quads) + tuple(textured)):
        args = (ql, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, u[:, q])
        if kernel:
            out += estimate_quad_fast(*args, heuristic=heuristic, control=control)
        else:
            out += estimate_quad(*args, heuristic=heuristic)
    return out


#: Sub-pixel positions per scratch buffer of :func:`reference_samples_kernel`.
BLOCK = 256


@njit_parallel
def reference_samples_kernel(cam, xy, types, params, mat_f, mat_i, data, info, tex, read, qv, qn,
                             qarea, qrect, qis_rect, qrad, base, m, keys, pixels, npairs, power,
                             view_z_min, cv, axis_t, axis_r, tab_m, tab_mag, tab_fres, rad):
    """:func:`shade_reference` for untextured quad lights fused with the surface of each
    sub-pixel position, without intermediate arrays: the surface seen through ``xy (N, 2)``
    (:func:`prefilter.render.kernels.surface_sample`, ``read`` at level 0), the view in its
    shading frame (:func:`prefilter.render.shading.local_view`), then per quad light
    ``qv (Q, 4, 3)``, ``qn (Q, 3)``, ``qarea (Q,)``, ``qrect (Q, RECT_WIDTH)``, ``qis_rect (Q,)``,
    ``qrad (Q, 3)`` its ``K = npairs`` MIS pairs
    (:func:`prefilter.render.estimator.material_mis_pair`, as
    :func:`prefilter.render.estimator.material_mis_kernel`).

    The pairs' uniforms are those of :func:`prefilter.render.estimator.owen_sobol` (Sobol table
    ``base (2^m, 2)``; light ``q``'s light samples keyed ``keys[2 q]``, its lobe samples
    ``keys[2 q + 1]``), drawn here: position ``i`` is position ``i % S`` of pixel
    ``pixels[i // S]`` (``S = N / len(pixels)``), and its pair ``j`` is point ``(i % S) K + j`` of
    the pixel's sets. Writes ``rad (N, 3)`` (0 on misses)."""
    n_pts = xy.shape[0]
    nq = qv.shape[0]
    npos = n_pts // pixels.shape[0]
    qc = np.empty((nq, 2))
    for q in range(nq):
        qc[q, 0], qc[q, 1] = quad_constants(qv[q], qn[q], qarea[q])
    n_blocks = (n_pts + BLOCK - 1) // BLOCK
    for blk in prange(n_blocks):
        gs = gscratch()
        tx = np.empty((2, 4))
        geo = np.empty((5, 3))
        mat = np.empty(7)
        cvar = np.zeros(13)
        mm = np.empty(9)
        P = np.empty((4, 3))
        C = np.empty((5, 3))
        # the scrambles of the current pixel's sets: (light, lobe) per quad light
        seeds = np.empty((2 * nq, 2), np.int64)
        shuffle = np.empty(2 * nq, np.int64)
        last = -1
        for i in range(blk * BLOCK, min(n_pts, (blk + 1) * BLOCK)):
            rad[i, 0] = 0.0
            rad[i, 1] = 0.0
            rad[i, 2] = 0.0
            hit, o, _r = surface_sample(cam, xy[i, 0], xy[i, 1], types, params, mat_f, mat_i,
                                        data, info, tex, read, gs, tx, geo, mat)
            if not hit:
                continue
            ts, bs, ns = geo[1], geo[2], geo[3]
            px, py, pz = geo[0, 0], geo[0, 1], geo[0, 2]
            # local_view: the view in the shading frame, clamped to z >= view_z_min
            wox = geo[4, 0] * ts[0] + geo[4, 1] * ts[1] + geo[4, 2] * ts[2]
            woy = geo[4, 0] * bs[0] + geo[4, 1] * bs[1] + geo[4, 2] * bs[2]
            woz = max(geo[4, 0] * ns[0] + geo[4, 1] * ns[1] + geo[4, 2] * ns[2], view_z_min)
            wn = np.sqrt(wox * wox + woy * woy + woz * woz)
            wox, woy, woz = wox / wn, woy / wn, woz / wn
            base_color, f0 = mat[1:4], mat[4:7]
            ax, ay = mat_f[o, 0], mat_f[o, 1]
            p_spec = specular_probability_jit(woz, base_color, f0)
            lam_o = ggx_lambda_jit(ax, ay, wox, woy, woz)
            use_cv = cv and ltc_control(wox, woy, woz, ax, ay, f0, axis_t, axis_r, tab_m,
                                        tab_mag, tab_fres, mm, cvar)
            if not use_cv:
                cvar[10] = cvar[11] = cvar[12] = 0.0
            pixel = pixels[i // npos]
            if pixel != last:
                for b in range(2 * nq):
                    shuffle[b] = owen_sobol_pixel(keys[b], pixel, seeds[b])
                last = pixel
            first = (i % npos) * npairs
            for q in range(nq):
                # views taken once per light, not per pair (each view costs reference counting)
                vq, nq_, rq = qv[q], qn[q], qrect[q]
                sl, sb = seeds[2 * q], seeds[2 * q + 1]
                shl, shb = shuffle[2 * q], shuffle[2 * q + 1]
                p1, d_plane = qc[q, 0], qc[q, 1]
                sr = quad_setup_jit(px, py, pz, rq, qis_rect[q])
                a0 = a1 = a2 = 0.0
                if use_cv:
                    # the control variate's integral, once per position: npairs times, as the
                    # sum below is divided by npairs
                    e = npairs * ltc_control_integral(px, py, pz, ts, bs, ns, vq, cvar, P, C)
                    a0, a1, a2 = cvar[10] * e, cvar[11] * e, cvar[12] * e
                for j in range(npairs):
                    kl = owen_sobol_index(first + j, shl, m)
                    kb = owen_sobol_index(first + j, shb, m)
                    r = material_mis_pair(px, py, pz, ts, bs, ns, wox, woy, woz, lam_o, ax, ay,
                                          base_color, f0, p_spec, vq, nq_, qarea[q], p1, d_plane,
                                          rq, sr, owen_sobol_coord(base, kl, 0, sl),
                                          owen_sobol_coord(base, kl, 1, sl),
                                          owen_sobol_coord(base, kb, 0, sb),
                                          owen_sobol_coord(base, kb, 1, sb), power, cvar)
                    a0 += r[0]
                    a0 += r[3]
                    a1 += r[1]
                    a1 += r[4]
                    a2 += r[2]
                    a2 += r[5]
                rad[i, 0] += a0 * (qrad[q, 0] / npairs)
                rad[i, 1] += a1 * (qrad[q, 1] / npairs)
                rad[i, 2] += a2 * (qrad[q, 2] / npairs)


def fused_shader(scene, lights: LightSet, textured, heuristic: str = "balance", control=None):
    """``callable(xy (N, 2), pixels (P,), n, K, seed) -> (N, 3)``:
    :func:`reference_samples_kernel` for ``scene`` (``n`` pairs per pixel, ``K`` per position),
    or ``None`` when the scene needs the staged path (point, directional or textured quad
    lights, no quad light, textures with too few channels). ``control``: the LTC table arrays of
    the control variate (:func:`prefilter.render.estimator.control_arrays`) or ``None``."""
    if lights.points or lights.directionals or textured or not lights.quads:
        return None
    packed = pack_materials(scene.objects)
    if packed is None:
        return None
    if heuristic not in HEURISTICS:
        raise ValueError(f"heuristic: expected one of {HEURISTICS}, got {heuristic!r}")
    types, params = pack_objects(scene.objects)
    read = level0_read(len(scene.objects))
    quads = lights.quads
    qv = np.ascontiguousarray([q.vertices for q in quads], dtype=np.float64).reshape(-1, 4, 3)
    qn = np.ascontiguousarray([q.normal for q in quads], dtype=np.float64).reshape(-1, 3)
    qa = np.ascontiguousarray([q.area for q in quads], dtype=np.float64)
    rects = [quad_rectangle(q.vertices) for q in quads]
    qrect = np.ascontiguousarray([np.zeros(RECT_WIDTH) if r is None else r for r in rects],
                                 dtype=np.float64).reshape(-1, RECT_WIDTH)
    qis = np.array([r is not None for r in rects], dtype=np.bool_)
    qr = np.ascontiguousarray([np.broadcast_to(q.radiance, 3) for q in quads],
                              dtype=np.float64).reshape(-1, 3)
    cam = camera_params(scene.camera)
    power = heuristic == "power"

    def shade(xy, pixels, n, k, seed):
        xy = np.ascontiguousarray(xy, dtype=np.float64)
        pixels = np.ascontiguousarray(pixels, dtype=np.int64)
        m = max(0, int(np.ceil(np.log2(max(n, 1)))))
        keys = np.array([sobol_key(seed, b) for q in range(len(quads)) for b in pair_blocks(q)],
                        dtype=np.int64)
        rad = np.empty((len(xy), 3))
        # always the parallel kernel, never its serial twin (jit.serial): the two compilations
        # can round differently (seen at 1e-15), and images must not depend on the chunk size
        reference_samples_kernel(
            cam, xy, types, params, *packed, read, qv, qn, qa, qrect, qis, qr,
            sobol_base(m, 2), m, keys, pixels, k, power, VIEW_Z_MIN, control is not None,
            *(NO_CONTROL if control is None else control), rad)
        return rad

    return shade


def pairs_per_position(spp: int, pairs: int = PAIRS_PER_POSITION) -> int:
    """Light/BRDF pairs shaded per sub-pixel position for ``spp`` pairs per pixel: ``pairs``
    (a power of two) once there are at least 16 positions left, fewer below, so small sample
    counts still cover the pixel."""
    k = pairs
    while k > 1 and spp // k < 16:
        k //= 2
    return k


#: Sample blocks of :func:`prefilter.render.estimator.owen_sobol`: sub-pixel positions, then two
#: per quad light (:func:`pair_blocks`).
POSITION_BLOCK = 0


def pair_blocks(q: int) -> tuple[int, int]:
    """The sample blocks of quad light ``q``'s light samples and lobe samples."""
    return POSITION_BLOCK + 1 + 2 * q, POSITION_BLOCK + 2 + 2 * q


@functools.lru_cache(maxsize=1)
def control_table() -> tuple:
    """The arrays of the shipped isotropic GGX LTC table
    (:func:`prefilter.render.estimator.control_arrays`), the reference's control variate; found
    through the registry's :data:`prefilter.render.methods.GGX_TABLE`."""
    from prefilter.render.methods import GGX_TABLE, resolve

    return control_arrays(resolve(GGX_TABLE)())


def render_reference(scene, settings, *, pairs: int | None = None,
                     heuristic: str = "balance", fused: bool = True,
                     clamp: bool = True) -> np.ndarray:
    """The ``reference`` method: ground truth for ``scene`` at ``settings.spp`` samples per pixel.

    Per pixel ``spp / K`` sub-pixel positions (whole pixel footprint), level-0 bilinear textures,
    and per position ``K = pairs_per_position(spp)`` MIS light/BRDF sample pairs per quad light,
    textured or not (:func:`shade_reference`); ``pairs`` overrides ``K``. The variant setting
    ``control`` (``settings.params``): ``"ltc"`` (default), the LTC control variate on
    untextured quads and ``K = 1``; ``"none"``, plain MIS and ``K = 4``. With the control
    variate a pixel's estimate can fall below zero at low sample counts; ``clamp`` (default)
    returns ``max(0, estimate)`` per pixel and channel, a bias confined to those pixels (the
    benchmark counts them: ``benchmarks/bench_reference_noise.py``). Returns ``(H, W, 3)``
    linear radiance; deterministic for a given ``settings.seed``.

    Scenes lit by untextured quad lights only run one Numba pass per row chunk
    (:func:`fused_shader`); others, or ``fused=False``, the NumPy stages (G-buffer,
    :func:`prefilter.render.driver.surface_attributes`, :func:`shade_reference`), which give the
    same image to rounding.
    """
    from prefilter.render.lighttex import split_lights

    lights, textured = split_lights(scene, "reference")
    nq = len(lights.quads) + len(textured)
    spp = settings.spp
    control = (control_table() if settings.param("control", "ltc") == "ltc" and lights.quads
               else None)
    # without quad lights there is nothing to pair: every sample is a sub-pixel position; with
    # the control variate the pairs' error is small, and positions are worth more than pairs
    k = ((pairs_per_position(spp, 1 if control else PAIRS_PER_POSITION) if nq else 1)
         if pairs is None else int(pairs))
    npos = -(-spp // k)
    # leave room for the K pairs of every position in a chunk
    settings = with_settings(settings, chunk_samples=max(1, settings.chunk_samples // k))

    def positions(rows, w):
        """Owen-scrambled Sobol sub-pixel positions of the chunk and its pixel indices."""
        rows = np.asarray(rows)
        pixels = (rows[:, None] * w + np.arange(w)[None, :]).reshape(-1)
        xy = owen_sobol(pixels, npos, 2, settings.seed, POSITION_BLOCK)
        xy = xy.reshape(len(rows), w, npos, 2) + np.asarray(settings.jitter)
        xy[..., 0] += np.arange(w, dtype=np.float64)[None, :, None]
        xy[..., 1] += rows.astype(np.float64)[:, None, None]
        return xy, pixels

    def pair_uniforms(pixels):
        """``(P npos, Q, K, 4)``: pair ``j`` of position ``i`` is point ``i K + j`` of the
        pixel's light-sample and lobe-sample sets (aligned runs of ``K``)."""
        return np.stack([np.concatenate([owen_sobol(pixels, npos * k, 2, settings.seed, b)
                                         for b in pair_blocks(q)], axis=-1).reshape(-1, k, 4)
                         for q in range(nq)], axis=1)

    def clamped(img):
        # with the control variate a pixel's estimate can fall below 0 (the samples subtracted
        # outweigh the exact integral added): radiance is never negative
        return np.maximum(img, 0.0, out=img) if control is not None and clamp else img

    shade = fused_shader(scene, lights, textured, heuristic, control) if fused else None
    if shade is not None:
        return clamped(render_positions(
            scene, settings, lambda xy, pixels: shade(xy, pixels, npos * k, k, settings.seed),
            desc="reference", positions=positions, per_pixel=npos))

    def radiance(xy, pixels):
        g = gbuffer_at(scene, xy)
        rad = np.zeros((g.hit.size, 3))
        if np.any(g.hit):
            u = pair_uniforms(pixels) if nq else np.zeros((g.hit.size, 0))
            gh = g.select(g.hit)
            a = surface_attributes(scene, gh, filtered=False)
            rad[g.hit] = shade_reference(gh.position, a["t"], a["b"], a["n"], gh.view,
                                         a["alpha_x"], a["alpha_y"], a["base_color"], a["f0"],
                                         lights, u[g.hit], textured=textured,
                                         heuristic=heuristic, control=control)
        return rad

    return clamped(render_positions(scene, settings, radiance, desc="reference",
                                    positions=positions, per_pixel=npos))
