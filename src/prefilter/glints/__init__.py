"""Glints: position-normal NDFs, the footprint pyramid, CP compression and constant-time queries.

Implements sections 3-4 of the glints tensor-prefiltering paper on top of Yan et al. 2016's
position-normal distributions. See ``docs/glints.md`` for conventions and measurements.

``pndf.pndf`` / ``pndf_image``: direct P-NDF; ``bake.bake``: normal map -> compressed pyramid
file; ``load``: validated :class:`GlintsMap`; ``point`` / ``range_mean`` (alias ``query.range``):
constant-time queries. ``bake`` and ``pndf`` are the submodules here, never their namesake
functions: a re-exported function would shadow the module (``import prefilter.glints.pndf as P``
would give the function, and ``P.TRUNCATION = 6`` silently set an attribute on it).
:class:`GlintSurface` (:mod:`prefilter.glints.surface`): a map with its normal map;
``glint_brdf_cos`` / ``glint_ndf`` (:mod:`prefilter.glints.brdf`): the BRDF and its footprint NDF;
``sample_wi``, ``sample_s``, ``ndf_pdf`` (:mod:`prefilter.glints.sample`): importance sampling.

Wang tiles (sec. 5.5, not imported here): :mod:`prefilter.glints.wang` (tile synthesis, implicit
tiling, direct P-NDF over tiles), :mod:`prefilter.glints.wang_ndf` (per-tile pyramids, queries,
sampling) and :mod:`prefilter.glints.wang_store` (``save_tiles`` / ``load_tiles``).
"""

from prefilter.glints import bake, pndf  # noqa: F401  (the submodules, as attributes)
from prefilter.glints.brdf import glint_brdf_cos, glint_ndf
from prefilter.glints.pndf import elements, hemisphere_ndf, pndf_image
from prefilter.glints.query import block_means, point, range_mean
from prefilter.glints.sample import ndf_pdf, sample_s, sample_s_direct, sample_wi
from prefilter.glints.store import GlintsMap, load
from prefilter.glints.surface import GlintSurface, surface

__all__ = ["GlintSurface", "GlintsMap", "block_means", "elements", "glint_brdf_cos", "glint_ndf",
           "hemisphere_ndf", "load", "ndf_pdf", "pndf_image", "point", "range_mean", "sample_s",
           "sample_s_direct", "sample_wi", "surface"]

