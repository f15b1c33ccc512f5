"""Glints at every path vertex: the glint lobe over a batch of footprints, for the path tracer.

The glints paper, sec. 5.3: "our method automatically solves the global illumination problem":
the footprint of a path vertex after glossy bounces is large (the path tracer's ray cone,
:mod:`prefilter.render.pathtrace`), and the compressed pyramid answers it in constant time where
the direct P-NDF (Yan et al. 2016) costs the footprint's area. ``glints`` and ``glints-direct``
with ``--param bounces=N`` (N > 1) path-trace the scene: objects with a normal map are shaded by
:class:`FootprintGlintLobe` (compressed or direct, as the method's direct renderer), the others
by the renderer's GGX material (:func:`prefilter.render.pathtrace.material_surface`). Each
vertex's footprint is the path's pixel footprint divided by the sample count
(:func:`prefilter.glints.render.footprints`), the paper's rule.
"""

from __future__ import annotations

import numpy as np

from prefilter.glints.brdf import FALLBACK_TRUNCATION, glint_brdf_cos
from prefilter.glints import render as direct_render
from prefilter.glints.render import baked_surface, footprints
from prefilter.glints.sample import n_uniforms, pdf_wi, sample_wi
from prefilter.lobe import Lobe, sample_weight
from prefilter.render.driver import two_sided_frame
from prefilter.render.pathtrace import (LobeUnion, PathOptions, PathStats, material_surface,
                                        path_options, render_paths)
from prefilter.sphere.sampling import cosine_hemisphere

__all__ = ["FootprintGlintLobe", "glint_surface", "render_glints", "render_glints_direct",
           "render_glints_paths"]


class FootprintGlintLobe(Lobe):
    """The glint BRDF (:func:`~prefilter.glints.brdf.glint_brdf_cos`) plus Lambert
    ``base_color``, one footprint per direction pair: ``center (N, 2)``, ``sigma_p (N,)``
    (texels) of ``surf`` (a :class:`~prefilter.glints.surface.GlintSurface`), ``f0, base_color
    (3,)``. Sampled by the footprint's NDF (:func:`~prefilter.glints.sample_wi`) with probability
    ``p_spec`` (the share of ``f0`` in ``f0 + base_color``, at least 0.05) and by the cosine lobe
    otherwise; ``fallback_truncation`` as :func:`~prefilter.glints.brdf.glint_ndf`. Results rgb
    ``(N, 3)``."""

    def __init__(self, surf, center, sigma_p, f0, base_color, *,
                 fallback_truncation: float | None = None):
        self.surf = surf
        self.center = np.asarray(center, dtype=np.float64)
        self.sigma_p = np.asarray(sigma_p, dtype=np.float64)
        self.f0 = np.asarray(f0, dtype=np.float64)
        self.base = np.asarray(base_color, dtype=np.float64)
        self.trunc = fallback_truncation
        s, d = float(self.f0.mean()), float(self.base.mean())
        self.p_spec = 1.0 if d <= 0.0 else min(max(s / (s + d), 0.05), 1.0)
        self.k = 3 if surf.gm is None else max(3, n_uniforms(surf.gm))
        self.n_uniforms = 1 + self.k

    def eval(self, wo, wi):
        if len(wo) == 0:
            return np.zeros((0, 3))
        spec = glint_brdf_cos(self.surf, self.center, self.sigma_p, wo, wi, self.f0,
                              fallback_truncation=self.trunc)
        return spec + self.base / np.pi * np.maximum(wi[:, 2], 0.0)[:, None]

    def pdf(self, wo, wi):
        if len(wo) == 0:
            return np.zeros(0)
        p = np.maximum(wi[:, 2], 0.0) / np.pi * (1.0 - self.p_spec)
        if self.p_spec > 0.0:
            p = p + self.p_spec * pdf_wi(self.surf, self.center, self.sigma_p, wo, wi)
        return p

    def sample(self, wo, u):
        n = len(wo)
        wi = -np.asarray(wo, dtype=np.float64).copy()
        spec = u[:, 0] < self.p_spec
        if np.any(spec):
            w, p = sample_wi(self.surf, self.center[spec], self.sigma_p[spec], wo[spec],
                             u=np.ascontiguousarray(u[spec, 1:1 + self.k]))
            ok = p > 0
            w = w / np.maximum(np.linalg.norm(w, axis=-1, keepdims=True), 1e-300)
            wi[spec] = np.where(ok[:, None], w, wi[spec])
        if not np.all(spec):
            wi[~spec] = cosine_hemisphere(u[~spec, 1:3])
        ok = np.sum(wi * wi, -1) > 0.5
        val = np.zeros((n, 3))
        pdf = np.zeros(n)
        if np.any(ok):
            val[ok], pdf[ok] = self.eval(wo[ok], wi[ok]), self.pdf(wo[ok], wi[ok])
        return wi, sample_weight(val, pdf)


def glint_surface(scene, mode: str, bake: dict | None = None):
    """``callable(g, spp) -> (lobe, frame)`` for :func:`prefilter.render.pathtrace.trace_paths`:
    objects with a normal map get a :class:`FootprintGlintLobe` in their geometric frame
    (``mode`` ``"compressed"``: the baked pyramid with the truncated fallback, as ``glints``,
    ``bake`` overriding its settings; ``"direct"``: the exact P-NDF of every footprint, as
    ``glints-direct``), the others the renderer's material."""
    material = material_surface(scene)
    glinty = np.array([o.material.normal_map is not None for o in scene.objects])
    trunc = FALLBACK_TRUNCATION if mode == "compressed" else None

    def at(g, spp):
        n = g.hit.size
        frame = [np.zeros((n, 3)) for _ in range(3)]
        parts = []
        gl = glinty[g.object_id]
        if not np.all(gl):
            m = ~gl
            lobe, fr = material(g.select(m), spp)
            for a, b in zip(frame, fr):
                a[m] = b
            parts.append((m, lobe))
        for k in np.unique(g.object_id[gl]):
            m = g.object_id == k
            gk = g.select(m)
            mat = scene.objects[int(k)].material
            surf = baked_surface(mat.normal_map.load(), direct=(mode == "direct"),
                                 settings=bake)
            c, sp = footprints(gk, surf.shape, spp)
            for a, b in zip(frame, two_sided_frame(gk)):
                a[m] = b
            parts.append((m, FootprintGlintLobe(surf, c, sp, mat.f0, mat.base_color,
                                                fallback_truncation=trunc)))
        return LobeUnion(parts, n), tuple(frame)

    return at


def render_glints_paths(scene, settings, mode: str, name: str, *,
                        options: PathOptions | None = None, stats: PathStats | None = None,
                        min_depth: int = 0) -> np.ndarray:
    """``glints`` / ``glints-direct`` with ``bounces > 1``: the path tracer with
    :func:`glint_surface`; ``min_depth=1`` keeps the indirect light only; ``stats`` collects the
    lobes' time per vertex. Returns ``(H, W, 3)`` float32."""
    opts = path_options(settings) if options is None else options
    bake = direct_render.bake_overrides(settings) if mode == "compressed" else None
    img = render_paths(scene, settings, glint_surface(scene, mode, bake), opts, desc=name,
                       stats=stats, min_depth=min_depth)
    return img.astype(np.float32)


def render_glints(scene, settings) -> np.ndarray:
    """The ``glints`` method: :func:`prefilter.glints.render.render_glints` (direct light), or
    with ``bounces > 1`` :func:`render_glints_paths` with the compressed pyramid."""
    if settings.param("bounces", "1") == "1":
        return direct_render.render_glints(scene, settings)
    direct_render.check_lights(scene, "glints")
    return render_glints_paths(scene, settings, "compressed", "glints")


def render_glints_direct(scene, settings) -> np.ndarray:
    """The ``glints-direct`` method: :func:`prefilter.glints.render.render_glints_direct`, or
    with ``bounces > 1`` :func:`render_glints_paths` with the direct P-NDF."""
    if settings.param("bounces", "1") == "1":
        return direct_render.render_glints_direct(scene, settings)
    direct_render.check_lights(scene, "glints-direct")
    return render_glints_paths(scene, settings, "direct", "glints-direct")
