"""Scene -> image: the one tiled driver every method runs on.

:func:`render` loads the scene if needed, looks the method up in
:mod:`prefilter.render.methods` and returns linear radiance ``(H, W, 3)`` float32.

:func:`render_positions` processes the image in chunks of whole rows (at most
``settings.chunk_samples`` samples each): ``spp`` sub-pixel positions per pixel, a method's
callable turns them into radiance per sample, and the driver averages per pixel. Every random
number of a row comes from its own generator (``SeedSequence(seed, spawn_key=(row,))``), so
images do not depend on the chunk size. :func:`render_samples` is the usual callable: trace the
positions (:func:`prefilter.render.camera.gbuffer_at`) and shade the hits over flat arrays.
Pixels whose samples miss every object are black (no background).

Surfaces are two-sided: a hit seen from behind its geometric normal is shaded with the frame
flipped (``n, b -> -n, -b``, still right-handed; :func:`two_sided_frame`).
:func:`surface_attributes` reads the materials' textures into a shading frame and material per
hit sample.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from prefilter.errors import PrefilterError
from prefilter.render.camera import gbuffer_at
from prefilter.render.methods import RenderSettings, check_params, get_method
from prefilter.render.scene import Scene, load_scene
from prefilter.texture.procedural import slopes_to_normals
from prefilter.validation import as_float_array, as_positive_int, check_memory

__all__ = ["estimate_render_bytes", "footprint_lookup", "render", "render_positions",
           "render_samples", "row_rng", "shading_frame", "stratified_offsets", "supported_lights",
           "surface_attributes", "two_sided_frame", "with_settings"]


def render(scene, method: str = "ltc", *, spp: int = 1, seed: int = 0, jitter=(0.0, 0.0),
           progress: bool = False, table=None, chunk_samples: int = 1 << 18,
           params=None, rows=None) -> np.ndarray:
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
    table : path, table object or None
        LTC table for LTC-based methods: a table file (``str`` or ``Path``, loaded by the
        method), an object with a ``lookup`` method (passed through) or ``None`` (the shipped
        table).
    params : dict or None
        The method's variant settings (:func:`prefilter.render.methods.method_params`), e.g.
        ``{"footprint": "paper"}`` for ``ltc-multiscale``.
    rows : (int, int) or None
        Only the image rows ``[r0, r1)``: the same bytes as those rows of the whole image (every
        row's random numbers are its own); methods that do not run on :func:`render_positions`
        render whole images only.

    Returns
    -------
    numpy.ndarray, shape (H, W, 3) (``(r1 - r0, W, 3)`` with ``rows``), float32
        Linear radiance.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    j = as_float_array(jitter, "jitter")
    if j.shape != (2,):
        raise PrefilterError(f"jitter: expected (dx, dy), got shape {j.shape}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise PrefilterError(f"seed: expected an integer >= 0, got {seed!r}")
    if table is not None and not (isinstance(table, (str, Path))
                                  or callable(getattr(table, "lookup", None))):
        raise PrefilterError("table: expected an LTC table file, a table object (with a lookup "
                             f"method) or None, got {type(table).__name__}")
    cam = scene.camera
    if rows is not None:
        ok = (len(rows) == 2 and all(isinstance(r, (int, np.integer)) for r in rows)
              and 0 <= rows[0] < rows[1] <= cam.height)
        if not ok:
            raise PrefilterError(f"rows: expected (r0, r1) with 0 <= r0 < r1 <= {cam.height} "
                                 f"(the image height), got {rows!r}")
        rows = (int(rows[0]), int(rows[1]))
    settings = RenderSettings(spp=as_positive_int(spp, "spp"), seed=int(seed),
                              jitter=(float(j[0]), float(j[1])), progress=bool(progress),
                              chunk_samples=as_positive_int(chunk_samples, "chunk_samples"),
                              table=table, params=check_params(method, params), rows=rows)
    check_memory(estimate_render_bytes(cam.width, cam.height, settings.spp,
                                       settings.chunk_samples),
                 f"render: a {cam.width} x {cam.height} image at {settings.spp} spp")
    image = get_method(method)(scene, settings)
    if rows is not None and np.shape(image)[0] != rows[1] - rows[0]:
        raise PrefilterError(f"rows: method {method!r} renders whole images only, expected no "
                             f"rows")
    return np.asarray(image, dtype=np.float32)


#: Bytes per pixel of the whole-image arrays of a render (about four float64 rgb images: the
#: driver's accumulator, a method's own, the float32 result and its temporaries).
IMAGE_BYTES_PER_PIXEL = 96
#: Bytes per shading sample in flight: G-buffer, frames, material and radiance arrays of one
#: chunk (measured peaks 1.2-2.0 KB per sample with tracemalloc for ltc, ltc-multiscale and
#: reference).
SAMPLE_BYTES = 2048


def estimate_render_bytes(width: int, height: int, spp: int, chunk_samples: int) -> int:
    """The memory a render needs, in bytes: the whole-image arrays plus one chunk of samples
    (:func:`render_positions` processes whole rows, at least one: ``max(chunk_samples,
    width * spp)`` samples, at most the image's)."""
    w, h, s = int(width), int(height), int(spp)
    per_chunk = min(max(int(chunk_samples), w * s), w * h * s)
    return IMAGE_BYTES_PER_PIXEL * w * h + SAMPLE_BYTES * per_chunk


def with_settings(settings: RenderSettings, **changes) -> RenderSettings:
    """A copy of ``settings`` with fields replaced (convenience for callers and tests)."""
    return replace(settings, **changes)


def supported_lights(scene: Scene, method: str):
    """The scene's :class:`~prefilter.render.lights.LightSet` for a method that shades only
    untextured quad, point and directional lights: environment maps and textured quad lights are
    rejected with a message naming the light. Methods that support more do not call it (the LTC
    methods take textured quads, :func:`prefilter.render.lighttex.split_lights`; the LEADR and
    glint methods take environment lights)."""
    for i, light in enumerate(scene.lights):
        if light.type == "environment" or getattr(light, "texture", None) is not None:
            what = "environment" if light.type == "environment" else "textured quad"
            raise PrefilterError(
                f"lights[{i}]: {what} lights are not supported by method {method!r}; expected "
                "untextured quad, point or directional lights")
    return scene.light_set()


# -- sample positions ----------------------------------------------------------------------------


def row_rng(seed: int, row: int) -> np.random.Generator:
    """The generator of image row ``row`` (independent of chunking)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(row,)))


def stratified_offsets(spp: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """Sub-pixel offsets ``(n, spp, 2)`` in ``[0, 1)^2``, stratified per pixel.

    A jittered ``k x k`` grid when ``spp = k^2``, otherwise Latin-hypercube (N-rooks) samples
    (each axis split into ``spp`` strata, one sample per stratum, y strata shuffled).
    """
    k = int(round(np.sqrt(spp)))
    if k * k == spp:
        i = np.arange(spp)
        base = np.stack([i % k, i // k], axis=-1).astype(np.float64)
        return (base[None] + rng.random((n, spp, 2))) / k
    sx = np.broadcast_to(np.arange(spp, dtype=np.float64), (n, spp))
    sy = rng.permuted(np.broadcast_to(np.arange(spp, dtype=np.float64), (n, spp)), axis=1)
    return (np.stack([sx, sy], axis=-1) + rng.random((n, spp, 2))) / spp


def chunk_positions(settings: RenderSettings, rows, w: int, stratified: bool,
                    random_dims: int = 0):
    """Sub-pixel sample positions ``xy (len(rows), W, S, 2)`` of image rows ``rows`` and, when
    ``random_dims > 0``, a list of ``(W * S, random_dims)`` uniforms per row, each row from its
    own generator (:func:`row_rng`)."""
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


def render_positions(scene: Scene, settings: RenderSettings, radiance, *, random_dims: int = 0,
                     stratified: bool = True, desc: str = "render", positions=None,
                     per_pixel: int | None = None) -> np.ndarray:
    """Drive a method over row chunks: sub-pixel positions in, per-pixel mean radiance out.

    Parameters
    ----------
    radiance : callable(xy, u) -> (N, 3)
        Radiance of the samples at pixel positions ``xy (N, 2)``; ``u`` is a list of
        ``(W * S, random_dims)`` uniforms per row of the chunk (empty when
        ``random_dims == 0``).
    random_dims : int
        Uniform numbers each sample needs.
    stratified : bool
        ``True``: ``spp`` stratified random positions per pixel (:func:`stratified_offsets`);
        ``False`` with ``spp == 1``: the pixel centre.
    positions : callable(rows, W) -> (xy (len(rows), W, S, 2), u) or None
        Replaces :func:`chunk_positions` (e.g. low-discrepancy points); its ``u`` is passed to
        ``radiance`` as is. ``per_pixel`` is then its ``S`` (default ``spp``).

    Returns
    -------
    numpy.ndarray, shape (H, W, 3), float64
        (``(r1 - r0, W, 3)`` when ``settings.rows = (r0, r1)``.)
    """
    cam = scene.camera
    h, w = cam.height, cam.width
    s = settings.spp if per_pixel is None else int(per_pixel)
    rows_per_chunk = max(1, settings.chunk_samples // (w * s))
    lo, hi = settings.rows or (0, h)
    image = np.zeros((hi - lo, w, 3))
    with tqdm(total=hi - lo, desc=desc, unit="row", delay=1.0, leave=False,
              disable=not settings.progress) as bar:
        # the chunks of the whole image, cut to the band: a band is its rows of the whole image
        for r0 in range(lo - lo % rows_per_chunk, hi, rows_per_chunk):
            rows = range(max(r0, lo), min(hi, r0 + rows_per_chunk))
            if positions is None:
                xy, us = chunk_positions(settings, rows, w, stratified, random_dims)
            else:
                xy, us = positions(rows, w)
            rad = radiance(xy.reshape(-1, 2), us).reshape(len(rows), w, s, 3)
            # the mean of one sample is that sample: skip the reduction
            image[rows.start - lo:rows.stop - lo] = rad[:, :, 0] if s == 1 else rad.mean(axis=2)
            bar.update(len(rows))
    return image


def render_samples(scene: Scene, settings: RenderSettings, shade, *, random_dims: int = 0,
                   stratified: bool = True, desc: str = "render") -> np.ndarray:
    """:func:`render_positions` through the G-buffer: trace the sub-pixel samples, shade hits.

    Parameters
    ----------
    shade : callable(g, u) -> (N, 3)
        Shades the flat G-buffer ``g`` of the hit samples; ``u (N, random_dims)`` are uniform
        numbers per sample (``None`` when ``random_dims == 0``).
    random_dims, stratified, desc
        As :func:`render_positions`.
    """

    def radiance(xy, us):
        g = gbuffer_at(scene, xy)
        rad = np.zeros((g.hit.size, 3))
        if np.any(g.hit):
            u = np.concatenate(us)[g.hit] if random_dims else None
            rad[g.hit] = shade(g.select(g.hit), u)
        return rad

    return render_positions(scene, settings, radiance, random_dims=random_dims,
                            stratified=stratified, desc=desc)


# -- surface attributes --------------------------------------------------------------------------


def two_sided_frame(g):
    """Geometric frames ``t, b, n`` ``(N, 3)`` of hit samples ``g`` (a G-buffer selection),
    flipped to the viewer's side: a two-sided surface seen from behind shades with ``-b, -n``
    (``t`` kept, so the frame stays right-handed)."""
    flip = np.where(np.sum(g.view * g.normal, -1) < 0.0, -1.0, 1.0)[:, None]
    return g.tangent, g.bitangent * flip, g.normal * flip


def shading_frame(frame_t, frame_b, frame_n, normal_ts=None):
    """Shading frame ``(t_s, b_s, n_s)``, each ``(N, 3)``, from a tangent-space normal.

    ``normal_ts (N, 3)`` (need not be unit: mip averages are shorter) is expressed in the geometric
    frame ``(t, b, n)``; the tangent is re-orthogonalised against the shading normal
    (Gram-Schmidt) so the anisotropy axes follow the surface's ``u`` direction, and the bitangent
    keeps the handedness of the geometric frame. ``None`` returns the geometric frame.
    """
    t = np.asarray(frame_t, dtype=np.float64)
    b = np.asarray(frame_b, dtype=np.float64)
    n = np.asarray(frame_n, dtype=np.float64)
    if normal_ts is None:
        return t, b, n
    m = np.asarray(normal_ts, dtype=np.float64)
    ns = m[..., 0:1] * t + m[..., 1:2] * b + m[..., 2:3] * n
    ln = np.linalg.norm(ns, axis=-1, keepdims=True)
    ns = np.where(ln > 1e-12, ns / np.maximum(ln, 1e-300), n)
    ts = t - np.sum(t * ns, axis=-1, keepdims=True) * ns
    lt = np.linalg.norm(ts, axis=-1, keepdims=True)
    # A shading normal along the tangent (never for sane maps): fall back to the bitangent side.
    alt = np.cross(b, ns)
    ts = np.where(lt > 1e-9, ts / np.maximum(lt, 1e-300), alt / np.linalg.norm(alt, axis=-1,
                                                                                keepdims=True))
    hand = np.where(np.sum(np.cross(n, t) * b, axis=-1, keepdims=True) >= 0.0, 1.0, -1.0)
    bs = hand * np.cross(ns, ts)
    return ts, bs, ns


#: Largest texture coordinate :func:`footprint_lookup` accepts (texture periods).
UV_MAX = 2.0**40


def footprint_lookup(chain, uv, dudv) -> np.ndarray:
    """``chain.lookup_footprint(uv, dudv)`` (isotropic trilinear) by a Numba kernel.

    ``chain``: a :class:`prefilter.texture.MipChain`; ``uv (N, 2)``, ``dudv (N, 2, 2)`` ->
    ``(N, C)``.
    """
    from prefilter.render.kernels import footprint_lookup_kernel, pack_mip, serial

    data, info = pack_mip(chain)
    c = chain.shape[2]
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    j = np.ascontiguousarray(dudv, dtype=np.float64).reshape(-1, 2, 2)
    # the kernel's texel indices are integers: keep it inside its domain (scenes give |uv| <=
    # prefilter.render.scene.UV_SCALE_MAX)
    if not (np.all(np.abs(uv) <= UV_MAX) and np.all(np.isfinite(j))):
        raise PrefilterError(f"uv, dudv: expected finite texture coordinates of magnitude <= "
                             f"{UV_MAX:g} and finite derivatives")
    out = np.empty((len(uv), c))
    serial(footprint_lookup_kernel, len(uv))(data, info, c, uv, j, out)
    return out


def surface_attributes(scene: Scene, g, *, filtered: bool = True, surface=None) -> dict:
    """Shading frame and material per hit sample of a flat G-buffer ``g``.

    ``filtered=True`` reads textures at the mip level of the pixel footprint (trilinear, isotropic
    LOD from ``g.dudv``: the naive prefiltering); ``False`` reads level 0 bilinearly (ground truth
    supersampling). Normal maps take precedence over height maps; a height map's normal is
    ``normalize(-s_x, -s_y, 1)`` of its (mean) slopes. A colour map multiplies ``base_color``.

    ``surface``: ``None`` or a method's own reading of the surface,
    ``callable(material, uv, dudv, t, b, n) -> dict`` for the samples of one object
    (``uv (M, 2)``, ``dudv (M, 2, 2)``, the two-sided geometric frame ``(M, 3)`` each); the
    arrays of the dict it returns replace or add to the attributes of those samples (without
    ``t, b, n`` the frame is read as above).

    Returns
    -------
    dict with ``t, b, n`` (N, 3) shading frame, ``alpha_x, alpha_y`` (N,), ``base_color, f0``
    (N, 3), plus the keys ``surface`` adds.
    """
    n_samples = g.hit.size
    out = {"t": np.zeros((n_samples, 3)), "b": np.zeros((n_samples, 3)),
           "n": np.zeros((n_samples, 3)), "alpha_x": np.zeros(n_samples),
           "alpha_y": np.zeros(n_samples), "base_color": np.zeros((n_samples, 3)),
           "f0": np.zeros((n_samples, 3))}
    gt, gb, gn = two_sided_frame(g)

    def tex(ref, m):
        if filtered:
            return footprint_lookup(ref.mip(), g.uv[m], g.dudv[m])
        return ref.mip().lookup(g.uv[m], 0.0)

    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        out["alpha_x"][m], out["alpha_y"][m] = mat.alpha_x, mat.alpha_y
        own = {} if surface is None else surface(mat, g.uv[m], g.dudv[m], gt[m], gb[m], gn[m])
        if not {"t", "b", "n"} <= own.keys():
            nts = None
            if mat.normal_map is not None:
                nts = tex(mat.normal_map, m)
            elif mat.height_map is not None:
                nts = slopes_to_normals(tex(mat.height_map, m)[:, :2])
            own = {**dict(zip("tbn", shading_frame(gt[m], gb[m], gn[m], nts))), **own}
        for key, value in own.items():
            if key not in out:
                out[key] = np.zeros((n_samples,) + np.shape(value)[1:])
            out[key][m] = value
        c = np.broadcast_to(mat.base_color, (int(m.sum()), 3))
        if mat.color_map is not None:
            cm = tex(mat.color_map, m)
            c = c * (cm[:, :3] if cm.shape[1] >= 3 else cm[:, :1])
        out["base_color"][m] = c
        out["f0"][m] = mat.f0
    return out
