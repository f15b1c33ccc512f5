"""The viewer's glint maps: built-in normal maps baked as the ``glints`` method bakes them
(:func:`prefilter.glints.render.baked_surface`, the render cache) and written for the page by
:func:`prefilter.glints.gpu.write_gpu` in every code variant.

The built-ins are small (:data:`GLINT_MAPS`, 64^2): a bake at the render's settings
(:data:`prefilter.glints.bake.BAKE_SETTINGS`, 512^2 NDF images, rank budget 48) takes minutes
per map on a loaded machine, once; later exports load it from the cache.
"""

from __future__ import annotations

from pathlib import Path

from prefilter.errors import PrefilterError

#: The glint mode's built-in maps (``prefilter.texture.normal_map`` kinds and parameters).
GLINT_MAPS = {kind: {"procedural": kind, "size": 64, "seed": 1}
              for kind in ("gaussian", "brushed", "flakes", "scratches")}


def glint_normal_map(kind: str):
    """The ``(H, W, 3)`` normal map of built-in ``kind`` (:data:`GLINT_MAPS`)."""
    from prefilter.texture import normal_map

    if kind not in GLINT_MAPS:
        raise PrefilterError(f"glint map: expected one of {sorted(GLINT_MAPS)}, got {kind!r}")
    spec = dict(GLINT_MAPS[kind])
    return normal_map(spec.pop("procedural"), **spec)


def glint_surface(kind: str, *, progress: bool = False):
    """The ``glints`` method's surface of built-in ``kind``: baked on first use (render cache,
    ``$PREFILTER_GLINTS_CACHE``), then loaded."""
    from prefilter.glints.render import baked_surface

    return baked_surface(glint_normal_map(kind), progress=progress)


def export_glints(out_dir, kinds=tuple(GLINT_MAPS), codes=("f32", "f16", "u8"), *,
                  limits: dict | None = None, progress: bool = False) -> dict:
    """Write the glint maps ``kinds`` in the code variants ``codes`` into ``out_dir`` (files
    ``glints_<kind>_<codes>_<texture>.bin``) and the glints GLSL (``glints.glsl``); returns the
    manifest entry ``{"glsl": "glints.glsl", "maps": {kind: {codes: write_gpu entry}}}``."""
    from prefilter.glints.gpu import export_surface, glsl_source, write_gpu

    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    (d / "glints.glsl").write_text(glsl_source())
    maps = {}
    for kind in kinds:
        surf = glint_surface(kind, progress=progress)
        maps[kind] = {c: write_gpu(export_surface(surf, codes=c, limits=limits), d,
                                   prefix=f"glints_{kind}_{c}") for c in codes}
    return {"glsl": "glints.glsl", "maps": maps}
