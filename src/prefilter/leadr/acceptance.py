"""Far-field acceptance: LEADR vs the displaced reference, the normal-mapped reference and naive
mip-mapped normal mapping, per footprint of 16 to 64 texels (a pixel far away).

For each surface (Gaussian height fields, isotropic slope std 0.1 to 0.5 and anisotropic), each
footprint size and several (view, light) pairs, the radiance of every method is compared with the
displaced reference (:func:`prefilter.leadr.displaced.displaced_radiance`). Flicker: the standard
deviation of a method's radiance over footprints shifted by a few texels (a camera pan), relative
to the reference's own variation (``|std_method - std_ref|`` would hide noise; we report the
std of ``method - reference`` over shifts, the part of the variation that is an error).
"""

from __future__ import annotations

import numpy as np

from prefilter.leadr.displaced import (cell_moments, displaced_radiance, naive_radiance,
                                       normal_mapped_radiance)
from prefilter.leadr.maps import shading_stats
from prefilter.leadr.shading import diffuse_directional, point_light
from prefilter.texture import height_map

SURFACES = {
    "iso 0.1": dict(kind="gaussian", rms_slope=0.1 * np.sqrt(2)),
    "iso 0.25": dict(kind="gaussian", rms_slope=0.25 * np.sqrt(2)),
    "iso 0.5": dict(kind="gaussian", rms_slope=0.5 * np.sqrt(2)),
    "aniso (0.45, 0.15)": dict(kind="anisotropic", cov=((0.2025, 0.0), (0.0, 0.0225))),
}


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


PAIRS = [(_unit([0.5, 0.1, 0.8]), _unit([-0.4, 0.2, 0.85])),
         (_unit([0.0, -0.6, 0.6]), _unit([0.1, 0.5, 0.75])),
         (_unit([0.7, 0.0, 0.45]), _unit([-0.6, 0.1, 0.6])),
         (_unit([0.2, 0.3, 0.9]), _unit([0.6, -0.3, 0.7]))]


def window_moments(cells, i0, j0, block):
    """Moments of the ``block x block`` cells starting at ``(i0, j0)`` (periodic)."""
    c = np.roll(cells, (-i0, -j0), axis=(0, 1))[:block, :block]
    return c.reshape(-1, 5).mean(axis=0)


def run(size: int = 256, blocks=(16, 32, 64), shifts: int = 4, k: int = 96, sigma_b: float = 0.1,
        seed: int = 0, log=print) -> list[dict]:
    """Rows of relative errors per surface, shading type and footprint (see module doc)."""
    rows = []
    for name, spec in SURFACES.items():
        params = dict(spec)
        kind = params.pop("kind")
        h = height_map(kind, size=size, seed=seed, corr_length=4.0, **params).height
        cells = cell_moments(h)
        for specular in (True, False):
            for block in blocks:
                err = {"leadr": [], "normal-mapped": [], "naive": []}
                dev = {m: [] for m in err}
                for wo, wi in PAIRS:
                    vals = {m: [] for m in ("ref",) + tuple(err)}
                    for s in range(shifts):
                        i0 = j0 = s * 3
                        # Lambertian micro-facets have no sub-texel roughness of their own.
                        mu, cov = shading_stats(window_moments(cells, i0, j0, block),
                                                sigma_b if specular else 0.0)
                        kw = dict(k=k, sigma_b=sigma_b, specular=specular)
                        ref = displaced_radiance(np.roll(h, (-i0, -j0), (0, 1)), block, 0, 0,
                                                 wo, wi, **kw)
                        vals["ref"].append(ref)
                        hr = np.roll(h, (-i0, -j0), (0, 1))
                        vals["normal-mapped"].append(
                            normal_mapped_radiance(hr, block, 0, 0, wo, wi, **kw))
                        vals["naive"].append(naive_radiance(hr, block, 0, 0, wo, wi, **kw))
                        if specular:
                            vals["leadr"].append(float(point_light(wo, wi, mu, cov)))
                        else:
                            vals["leadr"].append(float(diffuse_directional(wo, wi, mu, cov, 9)))
                    ref = np.asarray(vals["ref"])
                    for m in err:
                        v = np.asarray(vals[m])
                        err[m].append(np.abs(v - ref).mean() / ref.mean())
                        dev[m].append(np.std(v - ref) / ref.mean())
                row = {"surface": name, "shading": "specular" if specular else "diffuse",
                       "block": block}
                for m in err:
                    row[f"err {m}"] = float(np.mean(err[m]))
                    row[f"flicker {m}"] = float(np.mean(dev[m]))
                rows.append(row)
                log(row)
    return rows


def table(rows) -> str:
    """Markdown table of :func:`run`'s rows (relative errors in percent)."""
    out = ["| surface | shading | texels/pixel | LEADR err | normal-mapped err | naive err | "
           "LEADR / naive | LEADR flicker | naive flicker |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(
            f"| {r['surface']} | {r['shading']} | {r['block']} | {100 * r['err leadr']:.1f}% | "
            f"{100 * r['err normal-mapped']:.1f}% | {100 * r['err naive']:.1f}% | "
            f"{r['err leadr'] / max(r['err naive'], 1e-12):.2f} | "
            f"{100 * r['flicker leadr']:.2f}% | {100 * r['flicker naive']:.2f}% |")
    return "\n".join(out)
