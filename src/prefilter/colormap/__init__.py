"""Colour-map filtering (Heitz, Nowrouzezahrai, Poulin, Neyret 2013, "Filtering Color Mapped
Textures and Surfaces"); see ``docs/colormap.md``.

``table``: the pre-convolved 2D table (eq. 10) and its bilinear lookup; ``texture``: mean / std of
tabulated textures and procedural noise over footprints (section 4.2); ``height``: shadowing and
the height filtering distribution (section 5.1, eqs. 13-18); ``slope``: the view-dependent slope
filtering distribution and 2D slope tables (section 5.2); ``combine``: section 6; ``glsl``: the
shader snippet; ``commands``: ``prefilter bake colormap``.
"""

from prefilter.colormap.combine import combine_linear, combine_product
from prefilter.colormap.height import (
    OWN_PARAMS,
    PAPER_PARAMS,
    HeightParams,
    filter_height,
    fit_height_params,
    height_distribution,
    height_moments_approx,
    height_moments_exact,
    mean_visibility,
    smith_lambda,
    smith_lambda_direction,
)
from prefilter.colormap.slope import (
    SlopeColormapTable,
    filter_slope,
    slope_distribution,
    slope_prefilter_table,
)
from prefilter.colormap.table import (
    EDGES,
    ColormapTable,
    as_colormap,
    gaussian_operator,
    lookup,
    prefilter_table,
)
from prefilter.colormap.texture import (
    NoiseStd,
    filter_noise,
    filter_texture,
    moments_mip,
    naive_texture,
    texture_stats,
)

__all__ = [
    "EDGES", "ColormapTable", "HeightParams", "NoiseStd", "OWN_PARAMS", "PAPER_PARAMS",
    "SlopeColormapTable", "as_colormap", "combine_linear", "combine_product", "filter_height",
    "filter_noise", "filter_slope", "filter_texture", "fit_height_params", "gaussian_operator",
    "height_distribution", "height_moments_approx", "height_moments_exact", "lookup",
    "mean_visibility", "moments_mip", "naive_texture", "prefilter_table", "slope_distribution",
    "slope_prefilter_table", "smith_lambda", "smith_lambda_direction", "texture_stats",
]
