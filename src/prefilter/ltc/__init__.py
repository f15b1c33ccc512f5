"""Linearly transformed cosines: the distribution, polygon integration and GGX tables."""

from prefilter.ltc.ltc import LTC
from prefilter.sphere.polygon import (clamped_cosine_integral, polygon_integral,
                                      polygon_integral_minv)

__all__ = ["LTC", "clamped_cosine_integral", "polygon_integral", "polygon_integral_minv"]

from prefilter.ltc.table import GGXTable, schlick_scale  # noqa: E402

__all__ += ["GGXTable", "schlick_scale"]

from prefilter.ltc.aniso import AnisoGGXTable  # noqa: E402

__all__ += ["AnisoGGXTable"]
