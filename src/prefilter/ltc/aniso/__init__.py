"""LTC fit of anisotropic GGX (Kt, Dupuy, Heitz, "Bringing Linearly Transformed Cosines to
Anisotropic GGX"): SW fitting (:mod:`.fit`, needs PyTorch), alignment (:mod:`.align`),
symmetries (:mod:`.symmetry`), the 4D table (:mod:`.table`, :mod:`.bake`), engine layouts and
GLSL (:mod:`.export`), acceptance (:mod:`.accept`). See ``docs/ltc-aniso.md``."""

from prefilter.ltc.aniso.table import AnisoGGXTable

__all__ = ["AnisoGGXTable"]
