"""Scene -> image for a registered method: the row-chunk driver, surface attributes, ``ltc``.

:func:`render` loads the scene if needed, looks the method up in
:mod:`prefilter.render.methods` and returns linear radiance ``(H, W, 3)`` float32.

Methods built on :func:`render_samples` trace ``spp`` sub-pixel positions per pixel through
:func:`prefilter.render.camera.gbuffer_at`, shade the hits over flat arrays, and average. Rows are
processed in chunks of at most ``settings.chunk_samples`` samples; every random number of a row
comes from its own generator (``SeedSequence(seed, spawn_key=(row,))``), so images do not depend on
the chunk size. Pixels whose samples miss every object are black (no background).

Surfaces are two-sided: a hit seen from behind its geometric normal is shaded with the frame
flipped (``n, b -> -n, -b``, still right-handed).

The ``ltc`` method with quad lights only runs one fused Numba kernel per row chunk (ray, hit,
footprint texture reads, shading frame, LTC shader; :func:`_render_ltc_fused`, shared with the
``ltc-multiscale`` methods, which only change the roughness); with point, directional or textured
quad lights it uses the stages above (G-buffer, :func:`surface_attributes`,
:func:`prefilter.render.shading.shade_ltc`), which give the same image for untextured lights.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from tqdm import tqdm

from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.render.camera import gbuffer_at
from prefilter.render.methods import RenderSettings, check_params, get_method
from prefilter.render.scene import Scene, load_scene
from prefilter.render.shading import shade_ltc, shading_frame, two_sided_frame
from prefilter.texture.procedural import slopes_to_normals


def render(scene, method: str = "ltc", *, spp: int = 1, seed: int = 0, jitter=(0.0, 0.0),
           progress: bool = False, table=None, chunk_samples: int = 1 << 18,
           params=None) -> np.ndarray:
    """Render ``scene`` (a :class:`Scene`, a JSON path or a dict) with the named method.

    Parameters
    ----------
    method : str
        A name from :func:`prefilter.render.methods.available` (``"ltc"``, ``"reference"``, ...).
    spp : int
        Samples per pixel.
    seed : int
        Seed of all random numbers: same inputs -> same bytes.
    jitter : (float, float)
        Camera offset in pixels (temporal-stability measurements).
    progress : bool
        tqdm progress bar for renders longer than a second.
    table : GGXTable or None
        LTC table for LTC-based methods (default: the shipped one); any object with a
        ``lookup`` method (a table-like object) is passed through.
    params : dict or None
        The method's variant settings (:func:`prefilter.render.methods.method_params`), e.g.
        ``{"footprint": "paper"}`` for ``ltc-multiscale``.

    Returns
    -------
    numpy.ndarray, shape (H, W, 3), float32
        Linear radiance.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    j = as_float_array(jitter, "jitter")
    if j.shape != (2,):
        raise PrefilterError(f"jitter: expected (dx, dy), got shape {j.shape}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise PrefilterError(f"seed: expected an integer >= 0, got {seed!r}")
    if table is not None and not callable(getattr(table, "lookup", None)):
        raise PrefilterError("table: expected an LTC table (prefilter.ltc.table.GGXTable, "
                             f"AnisoGGXTable) or None, got {type(table).__name__}")
    settings = RenderSettings(spp=as_positive_int(spp, "spp"), seed=int(seed),
                              jitter=(float(j[0]), float(j[1])), progress=bool(progress),
                              chunk_samples=as_positive_int(chunk_samples, "chunk_samples"),
                              table=table, params=check_params(method, params))
    image = get_method(method)(scene, settings)
    return np.asarray(image, dtype=np.float32)


def supported_lights(scene: Scene, method: str):
    """The scene's :class:`~prefilter.render.lights.LightSet` for a method that shades only
    untextured quad, point and directional lights: environment maps and textured quad lights are
    rejected with a message naming the light. Methods that support more do not call it: ``ltc``
    and the ``ltc-multiscale`` methods take textured quads
    (:func:`prefilter.render.lighttex.split_lights`), the ``leadr-env*`` / ``leadr-irradiance*``
    and ``glints*`` methods take environment lights."""
    for i, light in enumerate(scene.lights):
        if light.type == "environment" or getattr(light, "texture", None) is not None:
            what = "environment" if light.type == "environment" else "textured quad"
            raise PrefilterError(
                f"lights[{i}]: {what} lights are not supported by method {method!r}; expected "
                "untextured quad, point or directional lights")
    return scene.light_set()


def row_rng(seed: int, row: int) -> np.random.Generator:
    """The generator of image row ``row`` (independent of chunking)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(row,)))


def chunk_positions(settings: RenderSettings, rows, w: int, stratified: bool,
                    random_dims: int = 0):
    """Sub-pixel sample positions ``xy (len(rows), W, S, 2)`` of image rows ``rows`` and, when
    ``random_dims > 0``, a list of ``(W * S, random_dims)`` uniforms per row, each row from its
    own generator (:func:`row_rng`)."""
    from prefilter.render.reference import stratified_offsets

    s = settings.spp
    offs, us = [], []
    if not (stratified or s > 1 or random_dims):  # pixel centres: no random numbers needed
        offs = [np.full((len(rows), w, 1, 2), 0.5)]
        rows_ = []
    else:
        rows_ = rows
    for y in rows_:
        rng = row_rng(settings.seed, y)
        if stratified or s > 1:
            o = stratified_offsets(s, w, rng)
        else:
            o = np.full((w, 1, 2), 0.5)
        offs.append(o)
        if random_dims:
            us.append(rng.random((w * s, random_dims)))
    o = offs[0] if rows_ == [] else np.stack(offs)  # (rows, W, S, 2) in [0, 1)
    xy = o + np.asarray(settings.jitter, dtype=np.float64)
    xy[..., 0] += np.arange(w, dtype=np.float64)[None, :, None]
    xy[..., 1] += np.asarray(rows, dtype=np.float64)[:, None, None]
    return xy, us


def render_samples(scene: Scene, settings: RenderSettings, shade, *, random_dims: int = 0,
                   stratified: bool = True, desc: str = "render") -> np.ndarray:
    """Drive a method over row chunks: trace sub-pixel samples, shade hits, average per pixel.

    Parameters
    ----------
    shade : callable(g, u) -> (N, 3)
        Shades the flat G-buffer ``g`` of the hit samples; ``u (N, random_dims)`` are uniform
        numbers per sample (``None`` when ``random_dims == 0``).
    random_dims : int
        Uniform numbers each sample needs.
    stratified : bool
        ``True``: ``spp`` stratified random positions per pixel
        (:func:`prefilter.render.reference.stratified_offsets`); ``False`` with ``spp == 1``:
        the pixel centre.
    """
    cam = scene.camera
    h, w, s = cam.height, cam.width, settings.spp
    rows_per_chunk = max(1, settings.chunk_samples // (w * s))
    image = np.zeros((h, w, 3))
    with tqdm(total=h, desc=desc, unit="row", delay=1.0, leave=False,
              disable=not settings.progress) as bar:
        for r0 in range(0, h, rows_per_chunk):
            rows = range(r0, min(h, r0 + rows_per_chunk))
            xy, us = chunk_positions(settings, rows, w, stratified, random_dims)
            g = gbuffer_at(scene, xy).reshape(-1)
            rad = np.zeros((g.hit.size, 3))
            if np.any(g.hit):
                u = np.concatenate(us)[g.hit] if random_dims else None
                rad[g.hit] = shade(g.select(g.hit), u)
            rad = rad.reshape(len(rows), w, s, 3)
            # the mean of one sample is that sample: skip the reduction
            image[r0:r0 + len(rows)] = rad[:, :, 0] if s == 1 else rad.mean(axis=2)
            bar.update(len(rows))
    return image


def footprint_lookup(chain, uv, dudv) -> np.ndarray:
    """``chain.lookup_footprint(uv, dudv)`` (isotropic trilinear) by a Numba kernel.

    ``chain``: a :class:`prefilter.texture.MipChain`; ``uv (N, 2)``, ``dudv (N, 2, 2)`` ->
    ``(N, C)``.
    """
    from prefilter.render.kernels import footprint_lookup_kernel, pack_mip, serial

    data, info = pack_mip(chain)
    c = chain.shape[2]
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    out = np.empty((len(uv), c))
    serial(footprint_lookup_kernel, len(uv))(data, info, c, uv,
                            np.ascontiguousarray(dudv, dtype=np.float64).reshape(-1, 2, 2), out)
    return out


def surface_attributes(scene: Scene, g, *, filtered: bool):
    """Shading frame and material per hit sample of a flat G-buffer ``g``.

    ``filtered=True`` reads textures at the mip level of the pixel footprint (trilinear, isotropic
    LOD from ``g.dudv``: the naive prefiltering); ``False`` reads level 0 bilinearly (ground truth
    supersampling). Normal maps take precedence over height maps; a height map's normal is
    ``normalize(-s_x, -s_y, 1)`` of its (mean) slopes. A colour map multiplies ``base_color``.

    Returns
    -------
    dict with ``t, b, n`` (N, 3) shading frame, ``alpha_x, alpha_y`` (N,), ``base_color, f0``
    (N, 3).
    """
    n_samples = g.hit.size
    ts = np.zeros((n_samples, 3))
    bs = np.zeros((n_samples, 3))
    ns = np.zeros((n_samples, 3))
    ax = np.zeros(n_samples)
    ay = np.zeros(n_samples)
    base = np.zeros((n_samples, 3))
    f0 = np.zeros((n_samples, 3))
    gt, gb, gn = two_sided_frame(g)

    def tex(ref, m):
        if filtered:
            return footprint_lookup(ref.mip(), g.uv[m], g.dudv[m])
        return ref.mip().lookup(g.uv[m], 0.0)

    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        nts = None
        if mat.normal_map is not None:
            nts = tex(mat.normal_map, m)
        elif mat.height_map is not None:
            nts = slopes_to_normals(tex(mat.height_map, m)[:, :2])
        ts[m], bs[m], ns[m] = shading_frame(gt[m], gb[m], gn[m], nts)
        ax[m], ay[m] = mat.alpha_x, mat.alpha_y
        c = np.broadcast_to(mat.base_color, (int(m.sum()), 3))
        if mat.color_map is not None:
            cm = tex(mat.color_map, m)
            c = c * (cm[:, :3] if cm.shape[1] >= 3 else cm[:, :1])
        base[m] = c
        f0[m] = mat.f0
    return {"t": ts, "b": bs, "n": ns, "alpha_x": ax, "alpha_y": ay, "base_color": base,
            "f0": f0}


def render_ltc(scene: Scene, settings: RenderSettings) -> np.ndarray:
    """The ``ltc`` method: isotropic LTC table for quad lights, textures at the footprint's mip
    level (the naive method later methods improve on).

    Anisotropic materials use the isotropic table with ``alpha = sqrt(alpha_x alpha_y)``.
    With ``spp > 1`` the pixel is supersampled at stratified positions (same as the reference).
    Textured quad lights use the prefiltered light-texture lookup
    (:func:`prefilter.render.lighttex.shade_ltc_textured`, Heitz et al. 2016, section 5.3).
    """
    from prefilter.ltc.table import GGXTable
    from prefilter.render.lighttex import shade_ltc_textured, split_lights

    lights, textured = split_lights(scene, "ltc")
    table = settings.table if settings.table is not None else GGXTable.load()
    if not (lights.points or lights.directionals or textured):
        image = _render_ltc_fused(scene, settings, lights, table)
        if image is not None:
            return image

    def shade(g, _u):
        a = surface_attributes(scene, g, filtered=True)
        alpha = np.sqrt(a["alpha_x"] * a["alpha_y"])
        if textured:
            return shade_ltc_textured(g.position, a["t"], a["b"], a["n"], g.view, alpha,
                                      a["base_color"], a["f0"], lights, textured, table)
        return shade_ltc(g.position, a["t"], a["b"], a["n"], g.view, alpha, a["base_color"],
                         a["f0"], lights, table)

    return render_samples(scene, settings, shade, stratified=settings.spp > 1, desc="ltc")


def _render_ltc_fused(scene: Scene, settings: RenderSettings, lights, table, rough=None,
                      desc: str = "ltc"):
    """:func:`render_ltc` for quad lights only, one Numba pass per row chunk
    (:func:`prefilter.render.kernels.ltc_samples_kernel`): the same sample positions, footprint
    lookups, frames and shader as the NumPy stages, without intermediate arrays. ``None`` when
    the scene needs the general path (textures with too few channels, a table-like object).

    ``rough``: ``(rows (K, RGH_WIDTH), meso_tab)`` of the per-material roughness
    (:mod:`prefilter.render.kernels`; the ``ltc-multiscale`` methods), default ``ltc``'s."""
    from prefilter.render.camera import _camera_params
    from prefilter.render.kernels import (ltc_samples_kernel, pack_materials, pack_objects,
                                          plain_roughness, serial)
    from prefilter.render.shading import VIEW_Z_MIN

    if not all(hasattr(table, k) for k in ("axis_t", "axis_r", "M", "magnitude", "fresnel")):
        return None
    packed = pack_materials(scene.objects)
    if packed is None:
        return None
    rows, meso_tab = plain_roughness(len(scene.objects)) if rough is None else rough
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    meso_tab = np.ascontiguousarray(meso_tab, dtype=np.float64)
    types, params = pack_objects(scene.objects)
    quads = lights.quads
    qv = np.ascontiguousarray([q.vertices for q in quads], dtype=np.float64).reshape(-1, 4, 3)
    qn = np.ascontiguousarray([q.normal for q in quads], dtype=np.float64).reshape(-1, 3)
    qr = np.ascontiguousarray([q.radiance for q in quads], dtype=np.float64).reshape(-1, 3)
    tab = [np.ascontiguousarray(a, dtype=np.float64)
           for a in (table.axis_t, table.axis_r, table.M, table.magnitude, table.fresnel)]
    cam = scene.camera
    campar = _camera_params(cam)
    h, w, s = cam.height, cam.width, settings.spp
    rows_per_chunk = max(1, settings.chunk_samples // (w * s))
    image = np.zeros((h, w, 3))
    with tqdm(total=h, desc=desc, unit="row", delay=1.0, leave=False,
              disable=not settings.progress) as bar:
        for r0 in range(0, h, rows_per_chunk):
            chunk = range(r0, min(h, r0 + rows_per_chunk))
            xy, _ = chunk_positions(settings, chunk, w, settings.spp > 1)
            xy = np.ascontiguousarray(xy).reshape(-1, 2)
            rad = np.empty((len(xy), 3))
            status = np.zeros(len(xy), np.uint8)
            serial(ltc_samples_kernel, len(xy))(campar, xy, types, params, *packed, rows,
                                                meso_tab, qv, qn, qr, *tab, VIEW_Z_MIN, rad,
                                                status)
            if status.any():
                raise PrefilterError("table: expected invertible LTC matrices, got a singular "
                                     "interpolated one")
            rad = rad.reshape(len(chunk), w, s, 3)
            # the mean of one sample is that sample: skip the reduction
            image[r0:r0 + len(chunk)] = rad[:, :, 0] if s == 1 else rad.mean(axis=2)
            bar.update(len(chunk))
    return image


def with_settings(settings: RenderSettings, **changes) -> RenderSettings:
    """A copy of ``settings`` with fields replaced (convenience for callers and tests)."""
    return replace(settings, **changes)
