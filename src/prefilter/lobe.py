"""The interface every shading lobe speaks (pbrt's ``f`` / ``Sample_f`` / ``PDF`` triple).

A lobe is a cosine-weighted BRDF in a local shading frame (z = macro normal), batched over
arrays: directions are ``(..., 3)`` unit vectors, results ``(...,)`` (or ``(..., C)`` for coloured
lobes). GGX, non-centred Beckmann, LTC, the multi-scale and LEADR lobes and the glint BRDF all
implement it, so the Monte Carlo reference (:mod:`prefilter.render.reference`) and the sampling
tests (``tests/test_lobes.py``: chi-square and pdf consistency) treat them alike.

Contract, for ``wi, weight = lobe.sample(wo, u)``:

* ``pdf(wo, wi)`` is the density (solid angle) with which :meth:`Lobe.sample` draws ``wi``; it may
  put mass below the horizon (those samples come back with weight 0);
* ``weight == eval(wo, wi) / pdf(wo, wi)`` wherever ``pdf > 0``, and 0 elsewhere;
* ``eval(wo, wi)`` is ``f(wo, wi) max(0, wi_z)``, so ``E[weight] = albedo(wo)``; LTC lobes are
  the exception: their ``eval`` is the fitted distribution itself, whose small mass below the
  horizon their polygon integral also counts;
* a draw the sampler cannot complete (an empty footprint NDF, a reflection off a back-facing
  normal) returns a direction below the horizon with weight 0, so ``pdf`` integrates to the
  fraction of draws that succeed (1 for every analytic lobe).

Samplers take :attr:`Lobe.n_uniforms` uniforms per draw (2 except for the glint lobes, whose
hierarchical NDF sampler needs one per level).
"""

from __future__ import annotations

import numpy as np


class Lobe:
    """Base class of every lobe: subclasses provide :meth:`eval`, :meth:`sample`, :meth:`pdf`."""

    #: Uniform numbers :meth:`sample` takes per draw (the last axis of ``u``).
    n_uniforms: int = 2

    def eval(self, wo, wi) -> np.ndarray:  # pragma: no cover - abstract
        """Cosine-weighted BRDF ``f(wo, wi) max(0, wi_z)`` for ``wo, wi (..., 3)``."""
        raise NotImplementedError

    def sample(self, wo, u) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        """Directions ``wi (..., 3)`` drawn from uniforms ``u (..., n_uniforms)`` and their weights
        ``eval / pdf`` ``(...,)`` (0 for directions below the horizon)."""
        raise NotImplementedError

    def pdf(self, wo, wi) -> np.ndarray:  # pragma: no cover - abstract
        """Density (solid angle) of :meth:`sample` at ``wi`` ``(...,)``."""
        raise NotImplementedError

    def albedo(self, wo) -> np.ndarray:
        """Directional albedo ``integral eval(wo, wi) dwi``; lobes where it is cheap override it."""
        raise NotImplementedError(f"{type(self).__name__} has no closed-form or cheap albedo")


def sample_weight(value, density) -> np.ndarray:
    """``value / density`` where ``density > 0``, else 0 (the weight of a drawn direction)."""
    value = np.asarray(value, dtype=np.float64)
    density = np.asarray(density, dtype=np.float64)
    ok = density > 0.0
    if value.ndim > density.ndim:
        ok = ok[..., None]
        density = density[..., None]
    return np.where(ok, value / np.where(ok, density, 1.0), 0.0)
