"""Shared spherical foundations: frames, warps (uniform, cosine) and the chi-square test."""

from prefilter.sphere.sampling import (
    cosine_hemisphere,
    cosine_hemisphere_pdf,
    frame_from_normal,
    spherical_direction,
    to_local,
    to_world,
    uniform_sphere,
    uniform_sphere_pdf,
)
from prefilter.sphere.chi2 import (Chi2Result, Warp, chi2_sphere, chi2_warped, lobe_cap, slope_warp,
                                   warp_integral)

__all__ = [
    "Chi2Result",
    "chi2_sphere",
    "chi2_warped",
    "slope_warp",
    "Warp",
    "warp_integral",
    "lobe_cap",
    "cosine_hemisphere",
    "cosine_hemisphere_pdf",
    "frame_from_normal",
    "spherical_direction",
    "to_local",
    "to_world",
    "uniform_sphere",
    "uniform_sphere_pdf",
]
