"""Roughness mip chains that keep a normal map's highlights (``prefilter bake roughness``).

:mod:`~prefilter.roughness.bake` turns the box-filtered mip chain of a normal map into a GGX
roughness per level, by Toksvig's factor, LEAN's slope variance or the multi-scale LTC
``alpha_total``; :mod:`~prefilter.roughness.commands` is the command line that writes the levels
as EXR / PNG files and as one DDS and one KTX2 texture with that mip chain.
"""

from prefilter.roughness.bake import (
    METHODS,
    alpha_lean,
    alpha_ltc,
    alpha_toksvig,
    as_normal_field,
    bake_roughness,
    load_normals,
)

__all__ = ["METHODS", "alpha_lean", "alpha_ltc", "alpha_toksvig", "as_normal_field",
           "bake_roughness", "load_normals"]
