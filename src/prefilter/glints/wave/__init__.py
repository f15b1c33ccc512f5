"""Glints under wave optics (glint paper sec. 4.1 with Yan et al. 2018): heightfields, the
coloured wave-optics NDF images of footprints, their compressed pyramid, queries, BRDF, sampling
and render methods (docs/glints-wave.md)."""
