"""A glinty surface: a compressed glints map and (optionally) the normal map it was baked from.

The BRDF (:mod:`prefilter.glints.brdf`), the samplers (:mod:`prefilter.glints.sample`) and the
environment lights (:mod:`prefilter.glints.envlight`) take a :class:`GlintSurface`: footprints at
or above :attr:`GlintSurface.sigma_min` use the compressed pyramid, smaller ones the direct P-NDF
of the normal map (Yan et al. 2016) when it is known.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.glints.pndf import (DEFAULT_ROUGHNESS, as_intrinsic_roughness, as_normal_map,
                                   elements, map_digest)
from prefilter.glints.pyramid import resample_min_sigma
from prefilter.glints.query import check_interp
from prefilter.glints.store import GlintsMap


@dataclass(frozen=True)
class GlintSurface:
    """A compressed glints map with (optionally) the normal map it was baked from.

    Build it with :func:`surface`. ``normal_map`` and ``elements_`` are ``None`` when the
    direct-P-NDF fallback below the finest level is not available (then level 0 is used).
    """

    gm: GlintsMap | None
    normal_map: np.ndarray | None
    elements_: tuple | None
    intrinsic_roughness: float
    interp: str = "resample"
    bilinear: bool = True

    @property
    def sigma0(self) -> float:
        return self.gm.pyramid.sigma0 if self.gm is not None else np.inf

    @property
    def sigma_min(self) -> float:
        """Footprint std below which :func:`prefilter.glints.brdf.glint_ndf` uses the direct
        P-NDF (when the normal map is known): ``sigma0``, or the smallest resampled std for
        ``interp="resample"``."""
        if self.gm is None:
            return np.inf
        if self.interp == "resample":
            return resample_min_sigma(self.gm.pyramid)
        return self.gm.pyramid.sigma0

    @property
    def shape(self) -> tuple[int, int]:
        if self.normal_map is not None:
            return self.normal_map.shape[:2]
        p = self.gm.pyramid
        return p.height, p.width


def surface(gm: GlintsMap | None = None, normal_map=None, *, check: bool = True,
            intrinsic_roughness: float | None = None, interp: str = "resample",
            bilinear: bool = True) -> GlintSurface:
    """Bundle a baked map and its normal map (the direct P-NDF for tiny footprints).

    ``gm=None`` gives a direct-only surface (every query by :func:`prefilter.glints.pndf.pndf`, the
    ``glints-direct`` method). ``check`` verifies that ``normal_map`` is the one ``gm`` was baked
    from (SHA-1 of the float64 normals recorded by the bake). ``intrinsic_roughness``: that of
    the direct P-NDF (default: the bake's, else Yan et al.'s 0.005). ``interp``: how
    :func:`prefilter.glints.brdf.glint_ndf` evaluates compressed footprints
    (:func:`prefilter.glints.query.weights`):
    ``"resample"`` (default; Gaussian resampling, the footprint's exact P-NDF up to compression)
    or ``"trilinear"`` (the paper's 8-image blend); ``bilinear``: NDF values interpolated between
    the stored pixel averages (default) instead of the pixel's value.
    """
    check_interp(interp)
    if gm is None and normal_map is None:
        raise PrefilterError("surface: expected a GlintsMap, a normal map, or both; got neither")
    if gm is not None and not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.load), got "
                             f"{type(gm).__name__}")
    nm = el = None
    if normal_map is not None:
        nm = as_normal_map(normal_map)
        el = elements(nm)
        if gm is not None and check:
            digest = map_digest(nm)
            baked = gm.header.get("map_sha1")
            if baked is not None and baked != digest:
                raise PrefilterError("normal_map: expected the normal map the glints map was baked "
                                     f"from (SHA-1 {baked[:12]}...), got one with SHA-1 "
                                     f"{digest[:12]}...")
    if gm is not None:
        sr = float(gm.header.get("settings", {}).get("intrinsic_roughness", DEFAULT_ROUGHNESS))
    else:
        sr = DEFAULT_ROUGHNESS
    if intrinsic_roughness is not None:
        sr = as_intrinsic_roughness(intrinsic_roughness)
    return GlintSurface(gm, nm, el, sr, interp, bool(bilinear))


def as_surface(surf) -> GlintSurface:
    """``surf`` as a :class:`GlintSurface`: a surface is returned as is, a :class:`GlintsMap`
    is wrapped by :func:`surface` (compressed queries only); anything else is an error."""
    if isinstance(surf, GlintSurface):
        return surf
    if isinstance(surf, GlintsMap):
        return surface(surf)
    raise PrefilterError(f"surf: expected a GlintSurface (prefilter.glints.surface.surface) or a "
                         f"GlintsMap, got {type(surf).__name__}")

