"""Far-field error of the roughness mip chains (:mod:`prefilter.roughness`) on the built-in maps.

A plane seen from far away under a distant light: one pixel covers one texel of mip level ``k``
(a ``2^k x 2^k`` block of level 0, the box the mip chain averages), view and light directions are
the same over the plane. The supersampled reference shades every level-0 texel with its own normal
and the base roughness and averages each block; the filtered image shades each level-``k`` texel
once, with the renormalised mean normal and the baked roughness (what a GPU does with the two mip
chains). Shading is GGX with height-correlated Smith masking, ``f cos`` in the shading normal's
frame (Fresnel 1). The error of a (map, method, level) is the relative RMSE
``||img - ref|| / ||ref||`` over all pixels of a fixed set of view / light pairs; ``"none"`` is
the plain mip chain (base roughness at every level), the error the methods remove.

``python -m prefilter.studies.roughness`` prints the table of ``docs/roughness.md``.
"""

from __future__ import annotations

import numpy as np

from prefilter.microfacet import GGX
from prefilter.roughness.bake import METHODS, bake_roughness
from prefilter.sphere.sampling import frame_from_normal
from prefilter.texture.mip import MipChain
from prefilter.texture.procedural import normal_map

__all__ = ["MAPS", "far_field_error", "lighting_pairs", "markdown_table",
           "roughness_error_table", "shade"]

#: The built-in maps of the table (:func:`prefilter.texture.procedural.normal_map` kinds).
MAPS = ("gaussian", "brushed", "flakes", "scratches")


def _direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def lighting_pairs() -> list[tuple[np.ndarray, np.ndarray]]:
    """View / light direction pairs ``(wo, wi)``, each ``(3,)``: views at 0, 40 and 70 degrees,
    lights at 0, 30 and 60 degrees, opposite (near the mirror direction) or at 90 degrees in
    azimuth."""
    return [(_direction(tv, 0.0), _direction(tl, dphi))
            for tv in (0.0, 40.0, 70.0) for tl in (0.0, 30.0, 60.0) for dphi in (180.0, 90.0)]


def shade(normals, alpha, wo, wi) -> np.ndarray:
    """Cosine-weighted GGX ``f(wo, wi) (n . wi)`` ``(...)`` of unit shading normals
    ``normals (..., 3)`` with roughness ``alpha (...)``, for tangent-space ``wo, wi (3,)``.

    Directions are expressed in each normal's frame (:func:`frame_from_normal`); zero where
    either is below that normal's horizon.
    """
    t, b = frame_from_normal(normals)
    n = np.asarray(normals, dtype=np.float64)

    def local(w):
        return np.stack([t @ w, b @ w, n @ w], -1)

    lo, li = local(np.asarray(wo, float)), local(np.asarray(wi, float))
    up = (lo[..., 2] > 1e-6) & (li[..., 2] > 1e-6)
    safe = np.array([0.0, 0.0, 1.0])
    lo = np.where(up[..., None], lo, safe)
    li = np.where(up[..., None], li, safe)
    a = np.maximum(np.asarray(alpha, dtype=np.float64), 1e-4)
    return np.where(up, GGX(a).eval(lo, li), 0.0)


def far_field_error(normals, alpha0: float, levels, methods=("none",) + METHODS) -> dict:
    """Relative RMSE of the far-field image per ``(method, level)`` (module docstring).

    ``normals (H, W, 3)`` unit, ``alpha0`` the base GGX roughness, ``levels`` mip levels.
    """
    chain = MipChain(normals).levels
    baked = {m: bake_roughness(normals, alpha0, m) for m in methods if m != "none"}
    num = {(m, k): 0.0 for m in methods for k in levels}
    den = dict.fromkeys(levels, 0.0)
    for wo, wi in lighting_pairs():
        full = MipChain(shade(normals, np.full(normals.shape[:2], alpha0), wo, wi)).levels
        for k in levels:
            ref = full[k][..., 0]
            mean = chain[k] / np.linalg.norm(chain[k], axis=-1, keepdims=True)
            den[k] += float(np.sum(ref * ref))
            for m in methods:
                a = np.full(ref.shape, alpha0) if m == "none" else baked[m][k]
                img = shade(mean, a, wo, wi)
                num[m, k] += float(np.sum((img - ref) ** 2))
    return {(m, k): float(np.sqrt(num[m, k] / den[k])) for m, k in num}


def roughness_error_table(size: int = 256, seed: int = 0, roughness: float = 0.3,
                          levels=(2, 4, 6), maps=MAPS) -> list[dict]:
    """Far-field errors of every method on the built-in maps: one row per (map, method).

    ``roughness`` is the base *perceptual* roughness (``alpha0 = roughness^2``). Each row:
    ``map``, ``method`` and ``rel_rmse`` = ``{level: relative RMSE}``.
    """
    alpha0 = roughness * roughness
    rows = []
    for kind in maps:
        err = far_field_error(normal_map(kind, size=size, seed=seed), alpha0, levels)
        for m in ("none",) + METHODS:
            rows.append({"map": kind, "method": m,
                         "rel_rmse": {k: err[m, k] for k in levels}})
    return rows


def markdown_table(rows) -> str:
    """The rows of :func:`roughness_error_table` as a Markdown table (relative RMSE in %)."""
    levels = list(rows[0]["rel_rmse"])
    head = "| map | method | " + " | ".join(f"level {k} ({2 ** k}x{2 ** k} texels)"
                                            for k in levels) + " |"
    out = [head, "|" + "---|" * (2 + len(levels))]
    for r in rows:
        out.append(f"| {r['map']} | {r['method']} | "
                   + " | ".join(f"{100 * r['rel_rmse'][k]:.1f} %" for k in levels) + " |")
    return "\n".join(out)


def main(argv=None) -> None:  # pragma: no cover - a table for the docs
    import argparse

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--roughness", type=float, default=0.3)
    args = p.parse_args(argv)
    print(markdown_table(roughness_error_table(args.size, args.seed, args.roughness)))


if __name__ == "__main__":  # pragma: no cover
    main()
