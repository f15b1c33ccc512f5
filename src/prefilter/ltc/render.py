"""The ``ltc`` render method: quad lights by the isotropic LTC table (Heitz et al. 2016), textures
read at the footprint's mip level (the naive method later methods improve on).

With quad lights only, one fused Numba kernel per row chunk does everything per sample (ray, hit,
footprint texture reads, shading frame, LTC shader; :func:`render_ltc_fused`, which the
``ltc-multiscale`` method runs with its own roughness). With point, directional or textured quad
lights it runs the renderer's stages (G-buffer, :func:`prefilter.render.driver.surface_attributes`,
:func:`prefilter.ltc.shading.shade_ltc`), which give the same image for untextured lights.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.jit import serial
from prefilter.ltc.lighttex import shade_ltc_textured
from prefilter.ltc.shading import TABLE_ARRAYS
from prefilter.ltc.table import as_table
from prefilter.render.camera import camera_params
from prefilter.render.driver import render_positions, render_samples, surface_attributes
from prefilter.render.lighttex import split_lights
from prefilter.render.shading import VIEW_Z_MIN

__all__ = ["render_ltc", "render_ltc_fused"]


def render_ltc(scene, settings) -> np.ndarray:
    """The ``ltc`` method (module docstring).

    Anisotropic materials use the isotropic table with ``alpha = sqrt(alpha_x alpha_y)``.
    With ``spp > 1`` the pixel is supersampled at stratified positions (same as the reference).
    Textured quad lights use the prefiltered light-texture lookup
    (:func:`prefilter.ltc.lighttex.shade_ltc_textured`, Heitz et al. 2016, section 5.3).
    """
    lights, textured = split_lights(scene, "ltc")
    table = as_table(settings.table)
    if not (lights.points or lights.directionals or textured):
        image = render_ltc_fused(scene, settings, lights, table)
        if image is not None:
            return image

    def shade(g, _u):
        a = surface_attributes(scene, g)
        alpha = np.sqrt(a["alpha_x"] * a["alpha_y"])
        return shade_ltc_textured(g.position, a["t"], a["b"], a["n"], g.view, alpha,
                                  a["base_color"], a["f0"], lights, textured, table)

    return render_samples(scene, settings, shade, stratified=settings.spp > 1, desc="ltc")


def render_ltc_fused(scene, settings, lights, table, read=None, kernel=None, kernel_args=(),
                     desc: str = "ltc"):
    """:func:`render_ltc` for quad lights only, one Numba pass per row chunk
    (:func:`prefilter.ltc.kernels.ltc_samples_kernel`): the same sample positions, footprint
    lookups, frames and shader as the NumPy stages, without intermediate arrays. ``None`` when
    the scene needs the general path (textures with too few channels, a table-like object).

    ``read (K, READ_WIDTH)``: the normal-map read per material
    (:mod:`prefilter.render.kernels`, default the isotropic footprint). ``kernel``: a kernel
    with the arguments of :func:`prefilter.ltc.kernels.ltc_samples_kernel` (the default) and
    ``kernel_args`` inserted after ``read``: the same shader with another roughness
    (:func:`prefilter.multiscale.kernels.multiscale_samples_kernel`)."""
    from prefilter.ltc.kernels import ltc_samples_kernel
    from prefilter.render.kernels import pack_materials, pack_objects, plain_read

    if not all(hasattr(table, k) for k in TABLE_ARRAYS):
        return None
    packed = pack_materials(scene.objects)
    if packed is None:
        return None
    kernel = ltc_samples_kernel if kernel is None else kernel
    read = np.ascontiguousarray(plain_read(len(scene.objects)) if read is None else read,
                                dtype=np.float64)
    kernel_args = [np.ascontiguousarray(a, dtype=np.float64) for a in kernel_args]
    types, params = pack_objects(scene.objects)
    quads = lights.quads
    qv = np.ascontiguousarray([q.vertices for q in quads], dtype=np.float64).reshape(-1, 4, 3)
    qn = np.ascontiguousarray([q.normal for q in quads], dtype=np.float64).reshape(-1, 3)
    qr = np.ascontiguousarray([q.radiance for q in quads], dtype=np.float64).reshape(-1, 3)
    tab = [np.ascontiguousarray(getattr(table, a), dtype=np.float64) for a in TABLE_ARRAYS]
    campar = camera_params(scene.camera)

    def radiance(xy, _u):
        xy = np.ascontiguousarray(xy)
        rad = np.empty((len(xy), 3))
        status = np.zeros(len(xy), np.uint8)
        serial(kernel, len(xy))(campar, xy, types, params, *packed, read, *kernel_args, qv, qn,
                                qr, *tab, VIEW_Z_MIN, rad, status)
        if status.any():
            raise PrefilterError("table: expected invertible LTC matrices, got a singular "
                                 "interpolated one")
        return rad

    return render_positions(scene, settings, radiance, stratified=settings.spp > 1, desc=desc)
