"""Glints: position-normal NDFs, the footprint pyramid, CP compression and constant-time queries.

Implements sections 3-4 of the glints tensor-prefiltering paper on top of Yan et al. 2016's
position-normal distributions. See ``docs/glints.md`` for conventions and measurements.
"""

from prefilter.glints.pndf import elements, hemisphere_ndf, pndf, pndf_image

__all__ = ["elements", "hemisphere_ndf", "pndf", "pndf_image"]
