"""The isotropic GGX LTC table in engine layouts (:mod:`.presets`), the shared resampling to the
engines' 64 x 64 grid (:mod:`.layout`) and compact encodings (:mod:`.compact`)."""

from prefilter.ltc.export.layout import (ENGINE_SIZE, VIEW_AXES, engine_nodes, inverse_texels,
                                         ltc_code_textures, resample, sphere_form_factor)
from prefilter.ltc.export.presets import PRESETS, export_preset, half_bits

__all__ = ["ENGINE_SIZE", "PRESETS", "VIEW_AXES", "engine_nodes", "export_preset", "half_bits",
           "inverse_texels", "ltc_code_textures", "resample", "sphere_form_factor"]
