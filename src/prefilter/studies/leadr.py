"""Far-field acceptance: LEADR vs the displaced reference, the normal-mapped reference and naive
mip-mapped normal mapping, per footprint of 16 to 64 texels (a pixel far away).

For each surface (Gaussian height fields, isotropic slope std 0.1 to 0.5 and anisotropic), each
footprint size and several (view, light) pairs, the radiance of every method is compared with the
displaced reference (:func:`prefilter.leadr.displaced.displaced_radiance`). Flicker: the standard
deviation of a method's radiance over footprints shifted by a few texels (a camera pan), relative
to the reference's own variation (``|std_method - std_ref|`` would hide noise; we report the
std of ``method - reference`` over shifts, the part of the variation that is an error).

:func:`run_env` does the same under the procedural environment (specular: Simplified Algorithm 1;
diffuse: SH irradiance + Simplified Algorithm 3) against
:func:`prefilter.leadr.displaced.displaced_env_radiance`. :func:`convergence` measures the N x N
grid against the paper's N = 128 grid (error and time per N). :func:`image_point` renders
images of planes and spheres under a point light (LEADR, normal-mapped reference, naive) against
the ray-traced displaced surface, with flicker over sub-pixel jitters; :func:`image_env` images of
a plane under the environment.
"""

from __future__ import annotations

import time

import numpy as np

from prefilter.leadr.displaced import (cell_moments, displaced_env_radiance, displaced_radiance,
                                       naive_env_radiance, naive_radiance,
                                       normal_mapped_env_radiance, normal_mapped_radiance)
from prefilter.leadr.envmap import (EnvMap, IrradianceMap, procedural_env, sh9_irradiance,
                                    sh9_project, texel_directions)
from prefilter.leadr.maps import shading_stats
from prefilter.leadr.shading import (diffuse_directional, diffuse_irradiance, diffuse_sh,
                                     env_specular, gaussian_grid, grid_normals, point_light)
from prefilter.microfacet import Beckmann
from prefilter.render.shading import shading_frames
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


#: Luminance weights (Rec. 709) for scalar errors of rgb radiance.
LUM = np.array([0.2126, 0.7152, 0.0722])


def exact_irradiance(env, m) -> np.ndarray:
    """Irradiance ``(..., C)`` at normals ``m (..., 3)`` by midpoint quadrature over the
    environment's level-0 texels (the SH-free irradiance map)."""
    d, omega = texel_directions(*env.levels[0].shape[:2])
    lw = (env.levels[0] * omega[..., None]).reshape(-1, env.levels[0].shape[2])
    return np.maximum(np.asarray(m) @ d.reshape(-1, 3).T, 0.0) @ lw


def _shadowing(mean, cov, wo, wi):
    """``G2 / G1 = (1 + Lambda(wo)) / (1 + Lambda(wo) + Lambda(wi))`` of the footprint's
    non-centred Beckmann slopes for directions ``wi (..., 3)`` (0 below the mean surface)."""
    model = Beckmann(mean, cov)
    lo = float(model.smith_lambda(wo))
    li = model.smith_lambda(wi)
    with np.errstate(invalid="ignore"):
        g = 1.0 / (1.0 + li / (1.0 + lo))  # 1 if the mesosurface faces away from wo
    return np.where(np.isfinite(li) & (wi[..., 2] > 0.0), g, 0.0)


def diffuse_exact(env, wo, mean, cov, n, shadowing: bool = False) -> np.ndarray:
    """Simplified Algorithm 3 with the exact irradiance of ``env`` instead of order-2 SH, for
    one view ``wo (3,)`` and one footprint; ``(C,)``. ``shadowing=True``: the irradiance of
    the paper's (non-simplified) Algorithm 2, each light direction weighted by the footprint's
    ``G2 / G1`` (the division by the projected-area sum already holds ``1 / (1 + Lambda_o)``)."""
    m, w, _ = grid_normals(mean, cov, n)
    s = w * np.maximum(m @ wo, 0.0) / m[..., 2]
    d, omega = texel_directions(*env.levels[0].shape[:2])
    d = d.reshape(-1, 3)
    lw = (env.levels[0] * omega[..., None]).reshape(-1, env.levels[0].shape[2])
    if shadowing:
        lw = lw * _shadowing(mean, cov, wo, d)[:, None]
    e = np.maximum(m @ d.T, 0.0) @ lw
    return (s @ e) / (s.sum() * np.pi)


def env_specular_shadowed(env, wo, mean, cov, n) -> np.ndarray:
    """The paper's Algorithm 1 *with* self-shadowing for one view ``wo (3,)`` and one footprint,
    ``(C,)`` (:func:`prefilter.leadr.shading.env_specular` with ``shadowing``)."""
    return env_specular(env, wo, mean, cov, n, shadowing=True)


def run_env(size: int = 256, blocks=(16, 32, 64), shifts: int = 4, k: int = 32, spp: int = 16,
            sigma_b: float = 0.1, n_grid: int = 9, env_rows: int = 64, shadowing: bool = True,
            seed: int = 0, surfaces=None, shadings=("specular", "diffuse"),
            log=print) -> list[dict]:
    """Far-field rows under the procedural environment (z = the mean plane's normal).

    Per surface, shading (specular micro-Beckmann ``sigma_b`` / Lambert), footprint and the four
    views of :data:`PAIRS`: the displaced reference (``k^2`` view rays, ``spp`` MIS samples with
    shadow rays each), the normal-mapped reference, naive mip-mapped normal mapping and LEADR
    (``n_grid^2`` grid; diffuse: order-2 SH irradiance), plus ``leadr shadowed`` (the paper's
    non-simplified Algorithms 1 / 2+3 with ``G2 / G1`` per sample; diffuse with the exact
    irradiance), ``leadr-env`` (what the render method computes: compiled Algorithm 1 with
    ``G2 / G1``, 9 x 9, or 17 x 17 for footprints with a slope std >= 0.35
    (:func:`~prefilter.leadr.render.env_specular_adaptive`); diffuse: the irradiance map
    (:class:`~prefilter.leadr.envmap.IrradianceMap`) on the 5 x 5 grid plus
    :func:`~prefilter.leadr.shading.diffuse_shadowing`), and for diffuse ``leadr-env SH`` (the
    same with order-2 SH instead of the map), ``leadr exact E`` (Simplified Algorithm 3 with the
    exact irradiance instead of SH), ``naive SH`` (SH irradiance at the naive normal) and
    ``naive E map`` (the irradiance map at the naive normal, what ``leadr-irradiance-naive``
    renders; ``naive`` is Monte Carlo of the exact environment at that normal). ``err``:
    relative RMSE of the luminance over views and shifts; ``bias``: mean signed error, relative;
    ``flicker``: std over the shifts of ``method - reference``, relative, averaged over views
    (includes the reference's MC noise).
    """
    from prefilter.leadr import render as lr
    from prefilter.leadr.shading import diffuse_shadowing

    env = EnvMap(procedural_env(env_rows))
    sh = sh9_project(env)
    irr = IrradianceMap(env)
    rows = []
    for name, spec in (surfaces or SURFACES).items():
        params = dict(spec)
        kind = params.pop("kind")
        h = height_map(kind, size=size, seed=seed, corr_length=4.0, **params).height
        cells = cell_moments(h)
        for specular in [sh == "specular" for sh in shadings]:
            for block in blocks:
                sq = {"leadr": 0.0, "leadr shadowed": 0.0, "leadr-env": 0.0,
                      "normal-mapped": 0.0, "naive": 0.0}
                if not specular:
                    sq.update({"leadr exact E": 0.0, "naive SH": 0.0, "leadr-env SH": 0.0,
                               "naive E map": 0.0})
                dev = {m: [] for m in sq}
                refs, bias = [], {}
                for v, (wo, _) in enumerate(PAIRS):
                    vals = {m: [] for m in ("ref",) + tuple(sq)}
                    for s in range(shifts):
                        i0 = j0 = s * 3
                        hr = np.roll(h, (-i0, -j0), (0, 1))
                        mu, cov = shading_stats(window_moments(cells, i0, j0, block),
                                                sigma_b if specular else 0.0)
                        kw = dict(k=k, sigma_b=sigma_b, specular=specular, seed=seed + 7 * s + v)
                        vals["ref"].append(displaced_env_radiance(
                            hr, block, 0, 0, wo, env, spp=spp, shadowing=shadowing, **kw) @ LUM)
                        vals["normal-mapped"].append(
                            normal_mapped_env_radiance(hr, block, 0, 0, wo, env, spp=spp, **kw)
                            @ LUM)
                        vals["naive"].append(naive_env_radiance(hr, block, 0, 0, wo, env, **kw)
                                             @ LUM)
                        if specular:
                            lv = env_specular(env, wo, mu, cov, n_grid)
                            vals["leadr-env"].append(float(lr.env_specular_adaptive(
                                env, wo, mu, cov, shadowing=True)[0] @ LUM))
                            vals["leadr shadowed"].append(
                                float(env_specular_shadowed(env, wo, mu, cov, n_grid) @ LUM))
                        else:
                            vals["leadr shadowed"].append(float(
                                diffuse_exact(env, wo, mu, cov, n_grid, shadowing=True) @ LUM))
                            lv = diffuse_sh(sh, wo, mu, cov, n_grid)
                            # the render method's diffuse: the irradiance map on its 5 x 5
                            # grid + the compiled shadowing correction
                            dg = lr.DIFFUSE_GRID
                            corr = diffuse_shadowing(env, wo, mu, cov, dg)
                            vals["leadr-env"].append(float(np.maximum(
                                diffuse_irradiance(irr, wo, mu, cov, dg) + corr, 0.0) @ LUM))
                            vals["leadr-env SH"].append(float(np.maximum(
                                diffuse_sh(sh, wo, mu, cov, dg) + corr, 0.0) @ LUM))
                            vals["leadr exact E"].append(
                                float(diffuse_exact(env, wo, mu, cov, n_grid) @ LUM))
                            nb = np.array([-mu[0], -mu[1], 1.0]) / np.hypot(1.0, np.hypot(*mu))
                            vals["naive SH"].append(float(sh9_irradiance(sh, nb) @ LUM) / np.pi)
                            vals["naive E map"].append(float(irr.lookup(nb) @ LUM) / np.pi)
                        vals["leadr"].append(float(lv @ LUM))
                    ref = np.asarray(vals["ref"])
                    refs.append(ref)
                    for m in sq:
                        d = np.asarray(vals[m]) - ref
                        sq[m] += float(np.sum(d * d))
                        bias[m] = bias.get(m, 0.0) + float(np.sum(d))
                        dev[m].append(np.std(d) / ref.mean())
                mean_ref = float(np.mean(refs))
                row = {"surface": name, "shading": "specular" if specular else "diffuse",
                       "block": block}
                for m in sq:
                    row[f"err {m}"] = np.sqrt(sq[m] / np.size(refs)) / mean_ref
                    row[f"flicker {m}"] = float(np.mean(dev[m]))
                    row[f"bias {m}"] = bias[m] / np.size(refs) / mean_ref
                rows.append(row)
                log(row)
    return rows


def area_env_radiance(height, block: int, wo, env, *, k: int = 96, spp: int = 64,
                      sigma_b: float = 0.1, step: float = 0.1, seed: int = 0) -> np.ndarray:
    """Radiance ``(C,)`` per projected area of exactly the ``block x block`` cells at the
    origin of the displaced surface (specular), without parallax: ``k x k`` surface points
    ``p = (x, y, h(x, y))`` on the block's grid, weighted by ``(n.wo) / (n_z wo_z)`` and their
    visibility towards ``wo`` (a ray marched from ``p``), shaded like
    :func:`~prefilter.leadr.displaced.displaced_env_radiance` (MIS, shadow rays). The view-ray
    reference sees the cells its rays hit, shifted by up to ``h tan(theta_o)`` texels; this one
    sees the cells whose moments LEADR is given."""
    from prefilter.leadr.displaced import (EnvSampler, block_points, env_estimates,
                                           gradient, march, normals)

    h = np.ascontiguousarray(height, dtype=np.float64)
    wo = np.asarray(wo, np.float64)
    rng = np.random.default_rng(seed)
    x, y = block_points(0, 0, block, k)
    ny, nx = h.shape
    fx, fy = np.floor(x), np.floor(y)
    tx, ty = x - fx, y - fy
    j0, i0 = fx.astype(np.int64) % nx, fy.astype(np.int64) % ny
    j1, i1 = (j0 + 1) % nx, (i0 + 1) % ny
    z = ((h[i0, j0] * (1 - tx) + h[i0, j1] * tx) * (1 - ty)
         + (h[i1, j0] * (1 - tx) + h[i1, j1] * tx) * ty)
    n = normals(gradient(h, x, y))
    hmax, hmin = float(h.max()), float(h.min())
    max_steps = int(4 * (ny + nx) / step) + 16
    eps = 1e-4
    c = np.ones_like(x)
    ts = march(h, x + eps * wo[0], y + eps * wo[1], z + eps * wo[2], c * wo[0], c * wo[1],
                c * wo[2], hmin - 1.0, hmax, step / max(np.hypot(wo[0], wo[1]), abs(wo[2])),
                max_steps)
    vis = ~np.isfinite(ts) & (n @ wo > 0)
    wgt = np.where(vis, (n @ wo) / n[:, 2] / wo[2], 0.0)
    px, py, pz = x[vis], y[vis], z[vis]

    def visible(q, wi):
        dn = step / np.maximum(np.hypot(wi[:, 0], wi[:, 1]), np.abs(wi[:, 2]))
        t2 = march(h, px[q] + eps * wi[:, 0], py[q] + eps * wi[:, 1], pz[q] + eps * wi[:, 2],
                    np.ascontiguousarray(wi[:, 0]), np.ascontiguousarray(wi[:, 1]),
                    np.ascontiguousarray(wi[:, 2]), hmin - 1.0, hmax, float(dn.min()), max_steps)
        return ~np.isfinite(t2)

    rad = env_estimates(env, EnvSampler(env), np.broadcast_to(wo, (int(vis.sum()), 3)), n[vis],
                         spp, rng, sigma_b, 1.0, True, visible, None)
    return (wgt[vis, None] * rad).sum(axis=0) / x.size


def _hist_lambda(slopes, mean, w):
    """Smith ``Lambda`` of an empirical slope distribution ``slopes (K, 2)`` for directions
    ``w (D, 3)``: ``E[(s.w_xy - w_z)_+] / (w_z - mean.w_xy)`` (the Gaussian case is supplemental
    3.2); ``inf`` below the mean surface."""
    num = np.maximum(slopes @ w[:, :2].T - w[:, 2], 0.0).mean(axis=0)
    d = w[:, 2] - w[:, :2] @ mean
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 0, num / d, np.inf)


def histogram_specular(env, height, block: int, wo, mean, cov, *, lam: str = "gauss",
                       k: int = 32, nb: int = 5, sigma_b: float = 0.1) -> float:
    """Algorithm 1 (luminance, F = 1) with the footprint's *actual* slope histogram instead of
    the Gaussian: the bilinear gradients at ``k x k`` points of the block, each convolved with
    the micro lobe (``nb x nb`` grid of std ``sigma_b``), projected-area weights, LOD per sample
    from the micro cell; ``G2 / G1`` from the footprint's Gaussian ``(mean, cov)`` (``lam =
    "gauss"``), from the histogram's own Smith ``Lambda`` (``"hist"``, 4096 slopes) or none
    (``"none"``: 0 below the plane only). Isolates what the Gaussian slope model costs."""
    from prefilter.leadr.displaced import block_points, gradient

    x, y = block_points(0, 0, block, k)
    s = gradient(np.asarray(height, np.float64), x, y)
    pg, wg, hg = gaussian_grid(nb)
    ox, oy = np.meshgrid(pg, pg)
    off = np.stack([ox.ravel(), oy.ravel()], -1) * sigma_b
    sl = (s[:, None, :] + off[None]).reshape(-1, 2)
    wt = np.tile(np.outer(wg, wg).ravel(), len(s)) / len(s)
    m = np.concatenate([-sl, np.ones((len(sl), 1))], -1)
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    dot = m @ wo
    area = wt * np.maximum(dot, 0.0) / m[:, 2]
    wi = 2.0 * dot[:, None] * m - wo
    jac = 4.0 * np.abs(dot) * np.abs(m[:, 2]) ** 3
    lod = 0.5 * np.log2(np.maximum(jac * hg * hg * sigma_b ** 2, 1e-300) / env.texel_solid_angle)
    rad = env.lookup(wi, lod) @ LUM
    if lam == "gauss":
        g = _shadowing(mean, cov, wo, wi)
    elif lam == "none":
        g = (wi[:, 2] > 0.0).astype(float)
    else:
        sub = sl[np.linspace(0, len(sl) - 1, min(len(sl), 4096)).astype(np.int64)]
        lo = _hist_lambda(sub, mean, wo[None])[0]
        li = np.concatenate([_hist_lambda(sub, mean, wi[a:a + 4096])
                             for a in range(0, len(wi), 4096)])
        with np.errstate(invalid="ignore"):
            g = 1.0 / (1.0 + li / (1.0 + lo))
        g = np.where(np.isfinite(li) & (wi[:, 2] > 0.0), g, 0.0)
    return float((area * g * rad).sum() / area.sum())


def specular_diagnosis(surface: str = "iso 0.5", blocks=(16, 32), size: int = 256,
                       shifts: int = 4, sigma_b: float = 0.1, k_hi: int = 96, spp_hi: int = 64,
                       seed: int = 0, log=print) -> list[dict]:
    """Why environment specular misses 0.5x naive at sigma 0.5 (16 / 32 texels): the
    :func:`run_env` footprints (same seeds for ``ref``) against variants of the reference
    (another seed; ``k_hi^2`` rays x ``spp_hi`` samples; :func:`area_env_radiance`, no
    parallax) and of LEADR (grid N = 9 / 17 / 33, LOD bias +-0.5, unshadowed, and
    :func:`histogram_specular`: the footprint's real slope histogram with Gaussian / histogram /
    no Smith shadowing). Rows per (block, reference): relative RMSE and bias of each variant."""
    from prefilter.leadr.displaced import naive_env_radiance

    env = EnvMap(procedural_env(64))
    params = dict(SURFACES[surface])
    kind = params.pop("kind")
    h = height_map(kind, size=size, seed=seed, corr_length=4.0, **params).height
    cells = cell_moments(h)
    rows = []
    for block in blocks:
        vals = {}
        put = lambda name, v: vals.setdefault(name, []).append(float(v))  # noqa: E731
        for v, (wo, _) in enumerate(PAIRS):
            for s in range(shifts):
                i0 = j0 = s * 3
                hr = np.roll(h, (-i0, -j0), (0, 1))
                mu, cov = shading_stats(window_moments(cells, i0, j0, block), sigma_b)
                kw = dict(sigma_b=sigma_b, specular=True)
                q = seed + 7 * s + v
                put("ref", displaced_env_radiance(hr, block, 0, 0, wo, env, k=32, spp=16, seed=q,
                                                  **kw) @ LUM)
                put("ref seed2", displaced_env_radiance(hr, block, 0, 0, wo, env, k=32, spp=16,
                                                        seed=1000 + q, **kw) @ LUM)
                put("ref hi", displaced_env_radiance(hr, block, 0, 0, wo, env, k=k_hi,
                                                     spp=spp_hi, seed=2000 + q, **kw) @ LUM)
                put("area ref hi", area_env_radiance(hr, block, wo, env, k=k_hi, spp=spp_hi,
                                                     sigma_b=sigma_b, seed=3000 + q) @ LUM)
                put("naive", naive_env_radiance(hr, block, 0, 0, wo, env, k=32, seed=q, **kw)
                    @ LUM)
                for n in (9, 17, 33):
                    put(f"leadr N{n}", env_specular(env, wo, mu, cov, n, shadowing=True) @ LUM)
                for b in (-0.5, 0.5):
                    put(f"leadr N9 lod bias {b:+}", env_specular(
                        env, wo, mu, cov, 9, shadowing=True, lod_bias=b) @ LUM)
                put("leadr N17 unshadowed", env_specular(env, wo, mu, cov, 17) @ LUM)
                for lam in ("gauss", "hist", "none"):
                    put(f"histogram D, {lam} Lambda", histogram_specular(
                        env, hr, block, wo, mu, cov, lam=lam, sigma_b=sigma_b))
        vals = {name: np.asarray(v) for name, v in vals.items()}
        for ref in ("ref", "ref hi", "area ref hi"):
            r = vals[ref]
            row = {"surface": surface, "block": block, "reference": ref}
            for name, v in vals.items():
                if name != ref:
                    row[f"err {name}"] = float(np.sqrt(np.mean((v - r) ** 2)) / r.mean())
                    row[f"bias {name}"] = float(np.mean(v - r) / r.mean())
            rows.append(row)
            log(row)
    return rows


def diagnosis_table(rows) -> str:
    """Markdown table of :func:`specular_diagnosis`'s rows: RMSE (bias) per variant."""
    names = [k[4:] for k in rows[0] if k.startswith("err ")]
    names = sorted({n for r in rows for n in (k[4:] for k in r if k.startswith("err "))},
                   key=lambda n: (names.index(n) if n in names else -1))
    out = ["| block | reference | " + " | ".join(names) + " |",
           "|---|---|" + "---|" * len(names)]
    for r in rows:
        out.append(f"| {r['block']} | {r['reference']} | " + " | ".join(
            f"{100 * r[f'err {n}']:.1f}% ({100 * r[f'bias {n}']:+.1f}%)" if f"err {n}" in r
            else "-" for n in names) + " |")
    return "\n".join(out)


def _cov(sx, sy, r=0.0):
    return np.array([[sx * sx, r * sx * sy], [r * sx * sy, sy * sy]])


CONVERGENCE_CASES = {
    "specular sigma 0.10": ("specular", _cov(0.1, 0.1)),
    "specular sigma 0.25": ("specular", _cov(0.25, 0.25)),
    "specular sigma 0.50": ("specular", _cov(0.5, 0.5)),
    "specular aniso (0.5, 0.1, r 0.5)": ("specular", _cov(0.5, 0.1, 0.5)),
    "diffuse SH sigma 0.10": ("sh", _cov(0.1, 0.1)),
    "diffuse SH sigma 0.25": ("sh", _cov(0.25, 0.25)),
    "diffuse SH sigma 0.50": ("sh", _cov(0.5, 0.5)),
    "diffuse directional sigma 0.50": ("directional", _cov(0.5, 0.5)),
}


def convergence(ns=(3, 5, 9, 17, 33), ref_n: int = 128, points: int = 1000, env_rows: int = 128,
                cases=None, seed: int = 0, log=print) -> list[dict]:
    """Relative RMSE (luminance) of the N x N grid against the ``ref_n`` grid, and time per point.

    ``points`` random configurations: views with ``wo_z`` uniform in [0.15, 1], mean slopes
    ``N(0, 0.15^2 I)``, under ``procedural_env(env_rows)`` (sky, sun, window stripes). Specular:
    Simplified Algorithm 1 (compiled kernel, F = 1, LOD bias 0); diffuse: Simplified Algorithm 3
    with SH irradiance or one directional light. Rows: ``case``, ``ref`` (mean luminance of the
    reference grid), per N ``err N`` and ``us N`` (wall-clock microseconds per point, best of 2,
    on whatever else the machine runs).
    """
    rng = np.random.default_rng(seed)
    cz = rng.uniform(0.15, 1.0, points)
    phi = rng.uniform(0.0, 2.0 * np.pi, points)
    sz = np.sqrt(1.0 - cz * cz)
    wo = np.stack([sz * np.cos(phi), sz * np.sin(phi), cz], -1)
    mu = rng.normal(scale=0.15, size=(points, 2))
    env = EnvMap(procedural_env(env_rows))
    sh = sh9_project(env)
    wl = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    rows = []
    for name, (kind, cov) in (cases or CONVERGENCE_CASES).items():
        def shade(n):
            if kind == "specular":
                return env_specular(env, wo, mu, cov, n) @ LUM
            if kind == "sh":
                return diffuse_sh(sh, wo, mu, cov, n) @ LUM
            return diffuse_directional(wo, wl, mu, cov, n)

        ref = shade(ref_n)
        row = {"case": name, "ref": float(ref.mean())}
        for n in ns:
            best = np.inf
            for _ in range(2):
                t = time.perf_counter()
                val = shade(n)
                best = min(best, time.perf_counter() - t)
            row[f"err {n}"] = float(np.sqrt(np.mean((val - ref) ** 2)) / np.mean(ref))
            row[f"us {n}"] = 1e6 * best / points
        rows.append(row)
        log(row)
    return rows


def convergence_table(rows, ns=(3, 5, 9, 17, 33)) -> str:
    """Markdown table of :func:`convergence`'s rows."""
    out = ["| case | " + " | ".join(f"N={n}" for n in ns) + " |",
           "|---|" + "---|" * len(ns)]
    for r in rows:
        out.append(f"| {r['case']} | " + " | ".join(
            f"{100 * r[f'err {n}']:.2f}% ({r[f'us {n}']:.1f} us)" for n in ns) + " |")
    return "\n".join(out)


def env_table(rows) -> str:
    """Markdown table of :func:`run_env`'s rows (relative RMSE in percent).

    Diffuse rows compare like with like for the ratio: LEADR and naive both with the exact
    irradiance (SH truncation is in the ``LEADR SH`` column)."""
    out = ["| surface | shading | texels/pixel | LEADR simplified | LEADR exact E | "
           "LEADR + shadowing | leadr-env | normal-mapped | naive | naive SH | "
           "simplified / naive | shadowed / naive | leadr-env / naive | leadr-env flicker | "
           "naive flicker |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    pc = _pc_key
    for r in rows:
        lead = "err leadr" if r["shading"] == "specular" else "err leadr exact E"
        out.append(
            f"| {r['surface']} | {r['shading']} | {r['block']} | {pc(r, 'err leadr')} | "
            f"{pc(r, 'err leadr exact E')} | {pc(r, 'err leadr shadowed')} | "
            f"{pc(r, 'err leadr-env')} | "
            f"{pc(r, 'err normal-mapped')} | {pc(r, 'err naive')} | {pc(r, 'err naive SH')} | "
            f"{r[lead] / max(r['err naive'], 1e-12):.2f} | "
            f"{r['err leadr shadowed'] / max(r['err naive'], 1e-12):.2f} | "
            f"{r['err leadr-env'] / max(r['err naive'], 1e-12):.2f} | "
            f"{100 * r['flicker leadr-env']:.2f}% | {100 * r['flicker naive']:.2f}% |")
    return "\n".join(out)


def env_diffuse_table(rows) -> str:
    """Markdown table of :func:`run_env`'s diffuse rows: ``leadr-env`` (irradiance map) and its
    order-2 SH variant against naive with the same representation: Monte Carlo of the exact
    environment (``naive``), the irradiance map (``naive E map``), order-2 SH (``naive SH``);
    signed biases and flickers (std over the shifts, includes the reference's noise)."""
    out = ["| surface | texels/pixel | leadr-env | leadr-env SH | LEADR + shadowing 9x9 | naive | "
           "naive E map | naive SH | leadr-env / naive | leadr-env / naive E map | "
           "leadr-env SH / naive SH | bias leadr-env / SH | flicker leadr-env / naive |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    pc = _pc_key
    ratio = lambda r, a, b: f"{r[f'err {a}'] / max(r[f'err {b}'], 1e-12):.2f}"  # noqa: E731
    for r in rows:
        if r["shading"] != "diffuse":
            continue
        out.append(
            f"| {r['surface']} | {r['block']} | {pc(r, 'err leadr-env')} | "
            f"{pc(r, 'err leadr-env SH')} | {pc(r, 'err leadr shadowed')} | "
            f"{pc(r, 'err naive')} | {pc(r, 'err naive E map')} | {pc(r, 'err naive SH')} | "
            f"{ratio(r, 'leadr-env', 'naive')} | {ratio(r, 'leadr-env', 'naive E map')} | "
            f"{ratio(r, 'leadr-env SH', 'naive SH')} | "
            f"{100 * r['bias leadr-env']:+.1f}% / {100 * r['bias leadr-env SH']:+.1f}% | "
            f"{100 * r['flicker leadr-env']:.2f}% / {100 * r['flicker naive']:.2f}% |")
    return "\n".join(out)


def image_env(sigma: float = 0.25, texels_per_pixel=(4.0, 16.0), width: int = 48,
              height: int = 32, sub: int = 8, spp: int = 16, sigma_b: float = 0.1,
              tex_size: int = 128, shadowing: bool = True, seed: int = 0,
              log=print) -> list[dict]:
    """Image-level comparison on a plane: the renderer's ``leadr-env`` (self-shadowing) /
    ``leadr-env`` with ``algorithm=simplified`` / ``leadr-env-naive`` (specular, f0 = 1) and
    ``leadr-irradiance`` / its simplified variant / ``-naive`` (diffuse) against the displaced
    plane rendered by :func:`prefilter.leadr.displaced.displaced_env_points`.

    The camera looks obliquely at a plane textured with a Gaussian height map (slope std
    ``sigma`` per axis, correlation length 4 texels) under ``procedural_env(64)`` placed by the
    scene convention; ``uv_scale`` is chosen so that a pixel at the image centre covers about
    ``texels_per_pixel`` texels. Reference: ``sub x sub`` sub-pixel rays per pixel, each traced
    to the displaced surface along its own direction, ``spp`` MIS samples per hit. Rows: relative
    RMSE (over hit pixels, / mean reference) and HDR-FLIP per method, the median footprint in
    texels, and the reference's own noise (RMSE between two seeds, relative).
    """
    import tempfile
    from pathlib import Path

    from prefilter.leadr import render as lr
    from prefilter.leadr.displaced import displaced_env_points
    from prefilter.leadr.envmap import ENV_FROM_WORLD
    from prefilter.render import load_scene
    from prefilter.render.camera import gbuffer_at
    from prefilter.render.methods import RenderSettings
    from prefilter.render.metrics import flip

    tmp = Path(tempfile.mkdtemp())
    np.save(tmp / "sky.npy", procedural_env(64))
    origin, fov, size = np.array([0.0, 2.0, 3.0]), 30.0, 40.0
    dist = float(np.linalg.norm(origin))
    # pixel footprint across the view at the target, stretched by 1 / cos(view, normal)
    pixel = dist * 2 * np.tan(np.radians(fov) / 2) / height / (origin[1] / dist)
    rows = []
    for tpp in texels_per_pixel:
        uv_scale = size / (tex_size * pixel / tpp)
        probe = load_scene({"camera": {"origin": origin.tolist(), "target": [0, 0, 0],
                                       "fov": fov, "width": width, "height": height},
                            "objects": [{"type": "plane", "size": size, "uv_scale": uv_scale}]})
        gp = gbuffer_at(probe, np.stack(np.meshgrid(np.arange(width) + 0.5,
                                                    np.arange(height) + 0.5), -1))
        # calibrate on the median footprint (sqrt of its area in texels)
        uv_scale *= tpp / np.median(np.sqrt(np.abs(np.linalg.det(gp.dudv[gp.hit]))) * tex_size)
        for specular in (True, False):
            mat = {"alpha": np.sqrt(2.0) * sigma_b if specular else 0.001,
                   "f0": 1.0 if specular else 0.0, "base_color": 0.0 if specular else 1.0,
                   "height_map": {"procedural": "gaussian", "size": tex_size, "seed": seed,
                                  "rms_slope": sigma * np.sqrt(2.0), "corr_length": 4.0,
                                  "scale": 1.0}}
            scene = load_scene({
                "camera": {"origin": origin.tolist(), "target": [0, 0, 0], "fov": fov,
                           "width": width, "height": height},
                "objects": [{"type": "plane", "size": size, "uv_scale": uv_scale,
                             "material": mat}],
                "lights": [{"type": "environment", "image": "sky.npy"}]}, base_dir=tmp)
            settings = RenderSettings()
            if specular:
                methods = {"leadr": lr.render_leadr_env,
                           "leadr simplified": lambda sc, st: lr.render_leadr_env(
                               sc, RenderSettings(params={"algorithm": "simplified"})),
                           "naive": lr.render_leadr_env_naive}
            else:
                methods = {"leadr": lr.render_leadr_irradiance,
                           "leadr simplified": lambda sc, st: lr.render_leadr_irradiance(
                               sc, RenderSettings(params={"algorithm": "simplified"})),
                           "naive": lr.render_leadr_irradiance_naive}
            imgs = {m: np.asarray(f(scene, settings), np.float64) for m, f in methods.items()}
            # reference: sub x sub rays per pixel through the displaced plane
            hmap = scene.objects[0].material.height_map.load().height
            s = (np.arange(sub) + 0.5) / sub
            oy, ox = np.meshgrid(s, s, indexing="ij")
            xy = np.stack(np.broadcast_arrays(
                np.arange(width)[None, :, None] + ox.ravel()[None, None, :],
                np.arange(height)[:, None, None] + oy.ravel()[None, None, :]), -1)
            g = gbuffer_at(scene, xy)
            hit = g.hit
            t, b, n = g.tangent[hit], g.bitangent[hit], g.normal[hit]
            wo = np.stack([np.sum(g.view[hit] * t, -1), np.sum(g.view[hit] * b, -1),
                           np.sum(g.view[hit] * n, -1)], -1)
            rot = ENV_FROM_WORLD @ np.stack([t[0], b[0], n[0]], -1)
            x = g.uv[hit][:, 0] * hmap.shape[1] - 0.5
            y = g.uv[hit][:, 1] * hmap.shape[0] - 0.5
            env = lr.scene_environment(scene)
            refs = []
            for sd in (seed, seed + 1):
                rad = np.zeros(hit.shape + (3,))
                rad[hit] = displaced_env_points(hmap, x, y, wo, env, rot=rot, spp=spp,
                                                sigma_b=sigma_b, specular=specular,
                                                shadowing=shadowing, seed=sd)
                refs.append(rad.mean(axis=2))
            ref = 0.5 * (refs[0] + refs[1])
            mask = hit.all(axis=2)
            mref = ref[mask].mean()
            fp = np.median(np.sqrt(np.abs(np.linalg.det(g.dudv[hit]))) * tex_size)
            row = {"sigma": sigma, "shading": "specular" if specular else "diffuse",
                   "texels/pixel": float(fp),
                   "ref noise": float(np.sqrt(np.mean((refs[0] - refs[1])[mask] ** 2)) / 2
                                      / mref)}
            for m, img in imgs.items():
                row[f"rmse {m}"] = float(np.sqrt(np.mean((img - ref)[mask] ** 2)) / mref)
                row[f"flip {m}"] = float(flip(np.where(mask[..., None], img, 0.0),
                                              np.where(mask[..., None], ref, 0.0)).mean)
            rows.append(row)
            log(row)
    return rows


# -- images under a point light: planes and spheres ------------------------------------------------

#: Height fields of :func:`image_point` (scene procedural specs; slope std per axis). ``aniso u``
#: is rougher along the tangent (the plane's x; on the sphere d p / d phi, along the circles of
#: latitude), ``aniso v`` along the bitangent (the sphere's meridians).
POINT_SURFACES = {
    "iso 0.1": dict(procedural="gaussian", rms_slope=0.1 * np.sqrt(2)),
    "iso 0.25": dict(procedural="gaussian", rms_slope=0.25 * np.sqrt(2)),
    "iso 0.5": dict(procedural="gaussian", rms_slope=0.5 * np.sqrt(2)),
    "aniso u (0.45, 0.15)": dict(procedural="anisotropic", cov=((0.2025, 0.0), (0.0, 0.0225))),
    "aniso v (0.15, 0.45)": dict(procedural="anisotropic", cov=((0.0225, 0.0), (0.0, 0.2025))),
}

#: Camera and point light per shape of :func:`image_point` (world +y up).
POINT_SHAPES = {
    "plane": dict(camera=dict(origin=[0.0, 2.0, 3.0], target=[0.0, 0.0, 0.0], fov=30.0),
                  obj=dict(type="plane", size=40.0),
                  light=dict(type="point", position=[0.4, 2.4, -3.2], intensity=12.0)),
    # close enough that the sphere fills the frame: the macro normal turns by ~0.03 rad per
    # pixel, which no texture filter sees (geometric aliasing, the same for every method)
    "sphere": dict(camera=dict(origin=[0.0, 0.4, 2.6], target=[0.0, 0.0, 0.0], fov=30.0),
                   obj=dict(type="sphere", center=[0.0, 0.0, 0.0], radius=1.0, pole=[0, 1, 0],
                            axis_x=[0, 0, -1]),
                   light=dict(type="point", position=[2.5, 2.5, 3.5], intensity=25.0)),
}


def _r2(k: int) -> np.ndarray:
    """Sub-pixel jitter ``(k, 2)`` in ``[-0.5, 0.5)^2``: the R2 sequence, first offset 0."""
    a = np.array([0.7548776662466927, 0.5698402909980532])
    return np.mod(0.5 + np.arange(k)[:, None] * a, 1.0) - 0.5


class _Fixed:
    """Per-sample moments ``(N, 5)`` standing in for a mip chain (``lookup_footprint``)."""

    def __init__(self, moments):
        self.moments = moments

    def lookup_footprint(self, uv, dudv, **_):
        return self.moments


def _point_scene(shape, width, height, scale, material, tmp=None):
    from prefilter.render import load_scene

    spec = POINT_SHAPES[shape]
    uv = [float(scale), float(scale)] if shape == "plane" else [2.0 * scale, float(scale)]
    return load_scene({"camera": dict(spec["camera"], width=width, height=height),
                       "objects": [dict(spec["obj"], uv_scale=uv, material=material)],
                       "lights": [spec["light"]]})


def image_point(surfaces=None, shapes=("plane", "sphere"), texels_per_pixel=(4.0, 16.0),
                width: int = 40, height: int = 30, sub: int | None = None, jitters: int = 8,
                sigma_b: float = 0.1, tex_size: int = 256, min_cos: float = 0.15,
                seed: int = 0, noise_floor: bool = False, log=print) -> list[dict]:
    """Image rows under one point light: LEADR (the renderer's shading code) vs the displaced
    height field, the normal-mapped reference and naive mip-mapped normal mapping.

    Per surface (:data:`POINT_SURFACES`, correlation length 4 texels, ``tex_size^2``), shape
    (:data:`POINT_SHAPES`: an oblique plane; a sphere with lat-long uv, ``uv_scale = (2 s, s)``
    so texels are square at the equator, the seam at the back) and footprint (``uv_scale`` set
    so the median pixel covers ``texels_per_pixel`` texels per side):

    * reference: ``sub x sub`` stratified camera rays per pixel (default ``max(8, tpp)``), each
      hitting the macro surface, then traced into the bilinear height field in that hit's
      tangent frame (texel units; :func:`prefilter.leadr.displaced.trace_points`) with a shadow
      ray towards the light; micro BRDF Beckmann ``sigma_b`` (specular, F = 1) or Lambert;
    * normal-mapped: the same rays shading the height field's normal at the macro hit;
    * ``leadr``: :func:`prefilter.leadr.render.shade_leadr_delta` (specular, closed form with
      G2) / :func:`~prefilter.leadr.render.shade_leadr_irradiance` (diffuse, Algorithm 3 with
      ``G2 / G1``), ``leadr simplified`` the diffuse without shadowing, at pixel centres, fed
      the exact moments of the traced bilinear surface (:func:`cell_moments`);
    * ``leadr-point``: what that method renders (one isotropic trilinear moment tap, diffuse
      without shadowing; the WebGL viewer's shading);
    * ``naive``: the same code with ``meso=False`` (mip-averaged normal, micro roughness).

    The largest footprint is rendered at ``jitters`` sub-pixel offsets (a camera shake; the
    reference follows): ``flicker`` = per-pixel std over the jitters of ``method - reference``,
    averaged over pixels, relative to the mean reference. Pixels count when every reference ray
    hits with ``wo_z >= min_cos``. Rows: relative RMSE (``rmse``) and HDR-FLIP (``flip``) per
    method (means over the jitters), ``flicker`` per method, ``ref noise`` (RMSE between two
    sub-ray patterns / 2, relative). Flicker rows also hold ``own flicker <method>`` (the std
    over the jitters of the image itself) and ``flicker ref`` (that of the reference: the score
    of a perfectly steady image).

    ``noise_floor``: the shifted sub-ray pattern is traced at every jitter of the largest
    footprint, giving ``flicker floor`` (the per-pixel std over the jitters of the two patterns'
    difference / sqrt 2, i.e. the flicker that the reference's own sampling error adds to any
    method's score, relative) and ``flicker2 <method>`` (flicker against the mean of the two
    patterns, whose floor is ``flicker floor / sqrt 2``).
    """
    from prefilter.leadr import render as lr
    from prefilter.leadr.displaced import gradient, micro, normals, trace_points
    from prefilter.render.camera import gbuffer_at
    from prefilter.render.metrics import flip
    from prefilter.texture import MipChain

    rows = []
    far = max(texels_per_pixel)
    for name, spec in (surfaces or POINT_SURFACES).items():
        params = dict(spec)
        kind = params.pop("procedural")
        hmap = height_map(kind, size=tex_size, seed=seed, corr_length=4.0, **params).height
        mips = {0: MipChain(cell_moments(hmap))}
        mats = {"specular": {"alpha": np.sqrt(2.0) * sigma_b, "f0": 1.0, "base_color": 0.0},
                "diffuse": {"alpha": 0.001, "f0": 0.0, "base_color": 1.0}}
        for shape in shapes:
            probe = _point_scene(shape, width, height, 1.0, mats["diffuse"])
            pix = np.stack(np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5), -1)
            gp = gbuffer_at(probe, pix)
            fp1 = np.median(np.sqrt(np.abs(np.linalg.det(gp.dudv[gp.hit])))) * tex_size
            for tpp in texels_per_pixel:
                scenes = {s: _point_scene(shape, width, height, tpp / fp1, m)
                          for s, m in mats.items()}
                sc = scenes["diffuse"]
                light = sc.light_set().points[0]
                ns = sub or max(8, int(np.ceil(tpp)))
                offs = _r2(jitters if tpp == far else 1)
                acc = {s: {} for s in mats}
                for k, o in enumerate(offs):
                    centre = pix + o
                    # reference rays: sub x sub strata per pixel (and a shifted pattern once)
                    pats = [0.0] + ([0.5] if k == 0 or (noise_floor and tpp == far) else [])
                    refs = {s: [] for s in mats}
                    box = None
                    for shift in pats:
                        s1 = (np.arange(ns) + 0.5 + shift) / ns - 0.5
                        sy, sx = np.meshgrid(s1, s1, indexing="ij")
                        xy = centre[:, :, None, :] + np.stack([sx.ravel(), sy.ravel()], -1)
                        g = gbuffer_at(sc, xy)
                        ok = g.hit.copy()
                        gh = g.select(ok)
                        t, b, n, wo = shading_frames(gh)
                        good = wo[:, 2] >= min_cos
                        d = light.position - gh.position
                        d2 = np.sum(d * d, -1)
                        wi = lr._local(d / np.sqrt(d2)[:, None], t, b, n)
                        x = gh.uv[:, 0] * tex_size
                        y = gh.uv[:, 1] * tex_size
                        hit, nm, lit = trace_points(hmap, x[good], y[good], wo[good], wi[good])
                        e = light.intensity[0] / d2[good]
                        nmap = normals(gradient(hmap, x[good], y[good]))
                        flat_ok = np.flatnonzero(ok.ravel())[good]
                        if box is None:
                            # the pixel's own moments: the box average over its rays' cells
                            cm = mips[0].levels[0]
                            cnt = ok.sum(axis=2)
                            mom = np.zeros(ok.shape + (5,))
                            mom[ok] = cm[np.floor(y).astype(np.int64) % tex_size,
                                         np.floor(x).astype(np.int64) % tex_size]
                            box = mom.sum(axis=2) / np.maximum(cnt, 1)[..., None]
                        mask = np.zeros(ok.size, bool)
                        mask[flat_ok] = True
                        pmask = mask.reshape(ok.shape).all(axis=2)
                        for s in mats:
                            spec_ = s == "specular"
                            v = np.zeros(len(nm))
                            v[hit] = micro(wo[good][hit], wi[good][hit], nm[hit], sigma_b, 1.0,
                                            spec_) * lit[hit]
                            nmv = micro(wo[good], wi[good], nmap, sigma_b, 1.0, spec_)
                            img = np.zeros(ok.size)
                            img[flat_ok] = v * e
                            nmi = np.zeros(ok.size)
                            nmi[flat_ok] = nmv * e
                            refs[s].append((img.reshape(ok.shape).mean(axis=2),
                                            nmi.reshape(ok.shape).mean(axis=2), pmask))
                    # the methods at the (jittered) pixel centres
                    gc = gbuffer_at(sc, centre)
                    gs = gc.select(gc.hit)
                    ls = sc.light_set()
                    meth = {}
                    fixed = {0: _Fixed(box[gc.hit])}
                    for s, scene in scenes.items():
                        if s == "specular":
                            vals = {"leadr": lr.shade_leadr_delta(scene, gs, ls, mips=mips),
                                    "leadr-point": lr.shade_leadr_delta(
                                        scene, gs, ls, mips=mips, shadowing=lr.POINT_SHADOWING,
                                        taps=lr.POINT_FOOTPRINT_TAPS),
                                    "leadr box": lr.shade_leadr_delta(scene, gs, ls, mips=fixed),
                                    "naive": lr.shade_leadr_delta(scene, gs, ls, meso=False,
                                                                  mips=mips)}
                        else:
                            z = np.zeros((9, 3))
                            vals = {"leadr": lr.shade_leadr_irradiance(
                                        scene, gs, z, ls, mips=mips),
                                    "leadr simplified": lr.shade_leadr_irradiance(
                                        scene, gs, z, ls, mips=mips, shadowing=False),
                                    "leadr-point": lr.shade_leadr_irradiance(
                                        scene, gs, z, ls, mips=mips,
                                        shadowing=lr.POINT_SHADOWING,
                                        taps=lr.POINT_FOOTPRINT_TAPS),
                                    "leadr one tap": lr.shade_leadr_irradiance(
                                        scene, gs, z, ls, mips=mips, shadowing=False, taps=1),
                                    "leadr box": lr.shade_leadr_irradiance(
                                        scene, gs, z, ls, mips=fixed),
                                    "naive": lr.shade_leadr_irradiance(
                                        scene, gs, z, ls, meso=False, mips=mips)}
                        meth[s] = {}
                        for m, v in vals.items():
                            im = np.zeros(gc.hit.shape)
                            im[gc.hit] = v[:, 0]
                            meth[s][m] = im
                    for s in mats:
                        ref, nmi, pmask = refs[s][0]
                        pmask = pmask & gc.hit
                        a = acc[s]
                        a.setdefault("mask", np.ones_like(pmask))
                        a["mask"] &= pmask
                        a.setdefault("ref", []).append(ref)
                        if len(refs[s]) > 1:
                            a.setdefault("ref2", []).append(refs[s][1][0])
                            a["mask"] &= refs[s][1][2]
                        for m, im in dict(meth[s], **{"normal-mapped": nmi}).items():
                            a.setdefault(m, []).append(im)
                for s in mats:
                    a = acc[s]
                    mask = a["mask"]
                    refs_k = np.asarray(a["ref"])
                    mref = float(refs_k[:, mask].mean())
                    row = {"surface": name, "shape": shape, "shading": s,
                           "texels/pixel": float(tpp), "pixels": int(mask.sum()),
                           "ref noise": float(np.sqrt(np.mean((a["ref2"][0] - refs_k[0])[mask]
                                                              ** 2) / 2) / mref)}
                    both = len(a["ref2"]) == len(refs_k) > 1

                    def jitter_std(x):  # (jitters, H, W) -> mean per-pixel std, relative
                        return float(np.mean(np.std(x[:, mask], axis=0)) / mref)

                    if both:
                        ref2 = np.asarray(a["ref2"])
                        row["flicker floor"] = float(np.mean(np.std(
                            (ref2 - refs_k)[:, mask], axis=0)) / np.sqrt(2.0) / mref)
                    # against the normal-mapped reference too (same rays, exact per-ray normals
                    # on the mean surface: no parallax, masking or shadowing): how well a method
                    # tracks the ideal filtered normal map
                    nm_k = np.asarray(a["normal-mapped"])
                    for m in [q for q in a if q not in ("mask", "ref", "ref2")]:
                        ims = np.asarray(a[m])
                        dif = (ims - refs_k)[:, mask]
                        row[f"rmse {m}"] = float(np.sqrt(np.mean(dif ** 2)) / mref)
                        row[f"flip {m}"] = float(np.mean([flip(
                            np.repeat(np.where(mask, im, 0.0)[..., None], 3, -1),
                            np.repeat(np.where(mask, rf, 0.0)[..., None], 3, -1)).mean
                            for im, rf in zip(ims, refs_k)]))
                        if len(ims) > 1:
                            row[f"flicker {m}"] = jitter_std(ims - refs_k)
                            # the image's own change under the shake, without the reference
                            row[f"own flicker {m}"] = jitter_std(ims)
                            if both:
                                row[f"flicker2 {m}"] = jitter_std(ims - 0.5 * (refs_k + ref2))
                            row[f"nm flicker {m}"] = jitter_std(ims - nm_k)
                    if len(refs_k) > 1:
                        # the flicker score of a perfectly steady image (the jitter-mean of the
                        # reference): what no filter can go below on this row
                        row["flicker ref"] = jitter_std(refs_k)
                    rows.append(row)
                    log(row)
    return rows


def point_table(rows) -> str:
    """Markdown table of :func:`image_point`'s rows: RMSE / FLIP per method, the LEADR / naive
    RMSE ratio and the flickers (where measured)."""
    out = ["| surface | shape | shading | texels/pixel | LEADR | LEADR box | LEADR simplified | "
           "leadr-point | normal-mapped | naive | LEADR / naive | leadr-point / naive | "
           "flicker LEADR / leadr-point / naive | flicker ratio | ref noise |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    cell = lambda r, m: (f"{100 * r[f'rmse {m}']:.1f}% / {r[f'flip {m}']:.3f}"  # noqa: E731
                         if f"rmse {m}" in r else "-")
    for r in rows:
        fl = "flicker leadr" in r
        out.append(
            f"| {r['surface']} | {r['shape']} | {r['shading']} | {r['texels/pixel']:.0f} | "
            f"{cell(r, 'leadr')} | {cell(r, 'leadr box')} | {cell(r, 'leadr simplified')} | "
            f"{cell(r, 'leadr-point')} | {cell(r, 'normal-mapped')} | {cell(r, 'naive')} | "
            f"{r['rmse leadr'] / max(r['rmse naive'], 1e-12):.2f} | "
            f"{r['rmse leadr-point'] / max(r['rmse naive'], 1e-12):.2f} | "
            + (f"{100 * r['flicker leadr']:.1f}% / {100 * r['flicker leadr-point']:.1f}% / "
               f"{100 * r['flicker naive']:.1f}% | "
               f"{r['flicker leadr'] / max(r['flicker naive'], 1e-12):.2f} | " if fl
               else "- | - | ")
            + f"{100 * r['ref noise']:.2f}% |")
    return "\n".join(out)


def _pc2(v) -> str:
    """A fraction as a percentage with 2 decimals."""
    return f"{100 * v:.2f}%"


def _pc_key(r, k) -> str:
    """``r[k]`` as a percentage with 1 decimal, ``-`` when missing."""
    return f"{100 * r[k]:.1f}%" if k in r else "-"


def flicker_table(rows) -> str:
    """Markdown table of the far flicker rows of :func:`image_point` run with ``noise_floor``:
    flicker of LEADR / naive / the normal-mapped reference against the displaced reference, the
    reference's own std over the jitters (the score of a steady image), the floor that the
    reference's sampling error puts under every method's score, and the same flickers against the
    mean of the two sub-ray patterns (floor / sqrt 2). ``reachable`` says whether the floor is
    below half the naive flicker (else no filter can meet flicker <= 0.5x naive on that row)."""
    out = ["| surface | shape | shading | LEADR | naive | normal-mapped | LEADR / naive | "
           "ref's own | floor | floor / naive | reachable | vs 2-pattern ref: LEADR / naive "
           "(ratio), floor |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    pc = _pc2
    for r in rows:
        if "flicker floor" not in r:
            continue
        fl, fn, f2l, f2n = (r["flicker floor"], r["flicker naive"], r["flicker2 leadr"],
                            r["flicker2 naive"])
        out.append(
            f"| {r['surface']} | {r['shape']} | {r['shading']} | {pc(r['flicker leadr'])} | "
            f"{pc(fn)} | {pc(r['flicker normal-mapped'])} | {r['flicker leadr'] / fn:.2f} | "
            f"{pc(r['flicker ref'])} | {pc(fl)} | {fl / fn:.2f} | "
            f"{'yes' if fl < 0.5 * fn else 'no'} | {pc(f2l)} / {pc(f2n)} ({f2l / f2n:.2f}), "
            f"{pc(fl / np.sqrt(2.0))} |")
    return "\n".join(out)


def flicker_source_table(rows) -> str:
    """Markdown table splitting the far flicker of :func:`image_point`'s rows by what it is
    measured against: the displaced reference (the acceptance's score) and the normal-mapped
    reference (the same rays with exact per-ray normals on the mean surface: no parallax,
    masking or shadowing), i.e. how far each method is from a perfect filter of the normal map.
    ``LEADR box`` shades the exact moments of the texels the reference's rays hit."""
    out = ["| surface | shape | shading | texels/pixel | vs displaced: LEADR / naive (ratio) | "
           "normal-mapped / naive | vs normal-mapped: LEADR / LEADR box / naive (ratio) | "
           "LEADR box / naive vs displaced |",
           "|---|---|---|---|---|---|---|---|"]
    pc = _pc2
    for r in rows:
        if "nm flicker leadr" not in r:
            continue
        fl, fn, fm = r["flicker leadr"], r["flicker naive"], r["flicker normal-mapped"]
        ml, mb, mn = r["nm flicker leadr"], r["nm flicker leadr box"], r["nm flicker naive"]
        out.append(
            f"| {r['surface']} | {r['shape']} | {r['shading']} | {r['texels/pixel']:.0f} | "
            f"{pc(fl)} / {pc(fn)} ({fl / fn:.2f}) | {pc(fm)} ({fm / fn:.2f}) | "
            f"{pc(ml)} / {pc(mb)} / {pc(mn)} ({ml / mn:.2f}) | "
            f"{r['flicker leadr box'] / fn:.2f} |")
    return "\n".join(out)
