"""Glints: position-normal NDFs, the footprint pyramid, CP compression and constant-time queries.

Implements sections 3-4 of the glints tensor-prefiltering paper on top of Yan et al. 2016's
position-normal distributions. See ``docs/glints.md`` for conventions and measurements.

``pndf.pndf`` / ``pndf_image``: direct P-NDF; ``bake.bake``: normal map -> compressed pyramid
file; ``load``: validated :class:`GlintsMap`; ``point`` / ``range_mean`` (alias ``query.range``):
constant-time queries. ``bake`` and ``pndf`` are the submodules here, never their namesake
functions: a re-exported function would shadow the module, so ``import prefilter.glints.pndf as
P`` gave the function and ``P.TRUNCATION = 6`` silently set an attribute on it.

Wang tiles (sec. 5.5, not imported here): :mod:`prefilter.glints.wang` (tile synthesis, implicit
tiling, direct P-NDF over tiles), :mod:`prefilter.glints.wang_ndf` (per-tile pyramids, queries,
sampling) and :mod:`prefilter.glints.wang_store` (``save_tiles`` / ``load_tiles``).
"""

from prefilter.glints import bake, pndf  # noqa: F401  (the submodules, as attributes)
from prefilter.glints.pndf import elements, hemisphere_ndf, pndf_image
from prefilter.glints.query import block_means, point, range_mean
from prefilter.glints.store import GlintsMap, load

__all__ = ["GlintsMap", "block_means", "elements", "hemisphere_ndf", "load", "pndf_image", "point",
           "range_mean"]

# part 2 (issue 9): BRDF and sampling
from prefilter.glints.brdf import GlintSurface, glint_brdf_cos, glint_ndf, surface  # noqa: E402
from prefilter.glints.sample import ndf_pdf, sample_s, sample_s_direct, sample_wi  # noqa: E402

__all__ += ["GlintSurface", "glint_brdf_cos", "glint_ndf", "ndf_pdf", "sample_s",
            "sample_s_direct", "sample_wi", "surface"]

