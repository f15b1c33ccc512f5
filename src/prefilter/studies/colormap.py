"""Acceptance scenes for colour-map filtering: a plane and a sphere carrying a colour map
driven by (a) tabulated noise, (b) procedural noise, (c) microsurface heights, (d) microsurface
slopes, rendered by the filtered method, the naive ``C(mean)`` and a 32 x 32 jittered supersampled
reference of the unfiltered function.

What is rendered is the filtered *colour* term of each case (``C0_bar`` of eq. 7, ``Ch_bar`` of
eq. 14 with the Smith visibility of eq. 2 towards a directional light, ``Cs_bar`` of eq. 19); the
other factors of eq. 1 multiply all methods alike. The reference evaluates, at every sub-pixel
sample, the level-0 (bilinear) driving texture and the paper's per-sample weights: eq. 14's
``V_o V_i / V_o`` for heights, eq. 19's projected area ``max(0, w_z - s . w_xy)`` for slopes.

"Near" and "far" are set by the texture density (texels per world unit) with fixed geometry:
for image content this is the same as moving the camera, and it keeps every pixel covered. The
footprint sizes reached are measured and reported (median texels per pixel, major axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prefilter.colormap.height import (
    filter_height_footprint,
    smith_lambda_direction,
)
from prefilter.colormap.slope import SlopeColormapTable, filter_slope, slope_prefilter_table
from prefilter.colormap.table import ColormapTable, prefilter_table
from prefilter.colormap.texture import NoiseStd, filter_noise, footprint_stats, texture_stats
from prefilter.texture.mip import MipChain, footprint_axes, moment_chain
from prefilter.texture.procedural import height_map, noise, noise_level_variance

__all__ = ["CASES", "AcceptanceData", "build_data", "lab_rmse", "render_case", "run_acceptance",
           "scene_dict"]

CASES = ("tabulated", "procedural", "height", "slope")
_LIGHT = np.array([0.4, 0.8, 0.45])  # towards the light (world, y up)


def _bands(v, stops, colours, width):
    """Piecewise-constant colours with smoothed steps of ``width`` at ``stops``."""
    out = np.broadcast_to(np.asarray(colours[0], float), v.shape + (3,)).copy()
    for s, c0, c1 in zip(stops, colours[:-1], colours[1:]):
        t = 0.5 + 0.5 * np.tanh((v - s) / width)
        out += t[..., None] * (np.asarray(c1, float) - np.asarray(c0, float))
    return out


def noise_colormap(v):
    """A strongly non-linear colour map of values ``~ N(0, 1)`` (bands, as the paper's fig. 5)."""
    return _bands(v, [-0.9, -0.2, 0.4, 1.1],
                  [(0.05, 0.1, 0.4), (0.9, 0.9, 0.85), (0.1, 0.45, 0.15), (0.95, 0.55, 0.1),
                   (0.5, 0.05, 0.05)], 0.04)


def height_colormap(x):
    """Colour by normalised height ``h / sigma_h``: water, sand, grass, rock, snow."""
    return _bands(x, [-1.0, -0.6, 0.5, 1.2],
                  [(0.05, 0.15, 0.5), (0.85, 0.8, 0.55), (0.15, 0.5, 0.1), (0.4, 0.3, 0.25),
                   (0.97, 0.97, 0.97)], 0.03)


def slope_colormap(s):
    """Colour by slope ``(s_x, s_y)``: grey where flat, blue / orange on facets facing -x / +x,
    a white cap on facets facing +y (deliberately asymmetric: its average is not ``C(0)``)."""
    sx, sy = s[..., 0], s[..., 1]
    out = _bands(sx, [-0.3, 0.3], [(0.1, 0.2, 0.7), (0.5, 0.5, 0.5), (0.95, 0.5, 0.05)], 0.04)
    cap = 0.5 + 0.5 * np.tanh((sy - 0.4) / 0.04)
    return out * (1 - cap[..., None]) + cap[..., None] * np.array([0.97, 0.97, 0.97])


@dataclass
class AcceptanceData:
    """Textures, their mip chains and the pre-filtered tables of the four cases."""

    noise: np.ndarray
    noise_mip: MipChain
    noise_moments: MipChain
    noise_std: NoiseStd
    noise_table: ColormapTable
    height: np.ndarray
    slopes: np.ndarray
    height_moments: MipChain
    slope_moments: MipChain
    sigma_h: float
    slope_cov: np.ndarray
    height_table: ColormapTable
    slope_table: SlopeColormapTable
    size: int


def build_data(size: int = 256, seed: int = 0) -> AcceptanceData:
    """Seeded textures: Gaussian noise (``corr_length`` 3 texels) and a Gaussian height field
    (rms slope 0.5, correlation length 4 texels), their moments mips and the colour tables."""
    f = noise(size, seed=seed, corr_length=3.0)
    hm = height_map("gaussian", size, seed=seed + 1, rms_slope=0.5, corr_length=4.0)
    sigma_h = float(hm.height.std())
    x = (hm.height - hm.height.mean()) / sigma_h
    s = hm.slopes
    cov = np.cov(s.reshape(-1, 2).T, bias=True)
    return AcceptanceData(
        noise=f, noise_mip=MipChain(f), noise_moments=moment_chain(f),
        noise_std=NoiseStd(noise_level_variance(size, 3.0), 1.0),
        noise_table=prefilter_table(noise_colormap, (-4.0, 4.0), 1.5, size=256),
        height=x, slopes=s, height_moments=moment_chain(x), slope_moments=moment_chain(s),
        sigma_h=1.0, slope_cov=cov,
        height_table=prefilter_table(height_colormap, (-4.5, 4.5), 1.5, size=256),
        slope_table=slope_prefilter_table(_slope_samples(96, 2.0), 2.0, 1.0, 32), size=size)


def _slope_samples(n, extent):
    x = -extent + (np.arange(n) + 0.5) * 2 * extent / n
    sx, sy = np.meshgrid(x, x)
    return slope_colormap(np.stack([sx, sy], -1))


def scene_dict(shape: str, view_deg: float, density: float, width: int = 48, height: int = 48):
    """A plane (seen at ``view_deg`` from its normal) or a sphere, textured at ``density``
    texels per world unit for a 256-texel texture."""
    if shape == "plane":
        t = np.radians(view_deg)
        cam = {"origin": [0.0, float(np.cos(t)), float(np.sin(t))], "target": [0, 0, 0],
               "up": [0.0, float(np.sin(t)), -float(np.cos(t))],
               "fov": 30, "width": width, "height": height}
        size = 40.0
        obj = {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "tangent": [1, 0, 0],
               "size": [size, size], "uv_scale": [density * size / 256] * 2}
    elif shape == "sphere":
        cam = {"origin": [0, 0, 2.6], "target": [0, 0, 0], "fov": 45, "width": width,
               "height": height}
        k = density * 2 * np.pi / 256  # texels per world unit along the equator
        obj = {"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "uv_scale": [k, k / 2]}
    else:
        raise ValueError(shape)
    return {"camera": cam, "objects": [obj], "lights": []}


def _local(g, w):
    """World directions ``w (..., 3)`` in the G-buffer's tangent frames."""
    return np.stack([np.sum(w * g.tangent, -1), np.sum(w * g.bitangent, -1),
                     np.sum(w * g.normal, -1)], -1)


def _upper(w):
    z = np.maximum(w[..., 2], 1e-3)
    w = np.concatenate([w[..., :2], z[..., None]], -1)
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


def shade_pixels(case: str, method: str, data: AcceptanceData, g) -> np.ndarray:
    """Filtered or naive colour at pixel centres (flat G-buffer), ``(N, 3)``."""
    uv, dudv = g.uv, g.dudv
    if case == "tabulated":
        mean, sigma = texture_stats(data.noise_moments, uv, dudv, anisotropic=True)
        return data.noise_table.lookup(mean, sigma if method == "filtered" else 0.0)
    if case == "procedural":
        filt, naive = filter_noise(data.noise_table, data.noise_mip, data.noise_std, uv, dudv,
                                   anisotropic=True)
        return filt if method == "filtered" else naive
    if case == "height":
        wo, wi = _upper(_local(g, g.view)), _upper(_local(g, np.broadcast_to(
            _LIGHT / np.linalg.norm(_LIGHT), g.view.shape)))
        lo = smith_lambda_direction(wo, data.slope_cov)
        li = smith_lambda_direction(wi, data.slope_cov)
        mu, var = footprint_stats(data.height_moments, uv, dudv, anisotropic=True)
        if method == "filtered":
            return filter_height_footprint(data.height_table, mu, np.sqrt(var), lo, li,
                                           data.sigma_h)
        # naive: the colour of the mean height, shadowed by the paper's mean visibility (eq. 13)
        return ((1 + lo) / (1 + lo + li))[..., None] * data.height_table.naive(mu)
    if case == "slope":
        wo = _upper(_local(g, g.view))
        mean, cov = footprint_stats(data.slope_moments, uv, dudv, anisotropic=True)
        if method == "filtered":
            return filter_slope(data.slope_table, wo, mean, cov)
        return data.slope_table.naive(mean)
    raise ValueError(case)


def _bilerp(tex, uv):
    """Bilinear, wrapped lookup of level 0 (the unfiltered function), ``(..., C)``."""
    if tex.ndim == 2:
        tex = tex[..., None]
    h, w = tex.shape[:2]
    x = uv[..., 0] * w - 0.5
    y = uv[..., 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    i0, j0 = np.mod(y0.astype(np.int64), h), np.mod(x0.astype(np.int64), w)
    i1, j1 = np.mod(i0 + 1, h), np.mod(j0 + 1, w)
    return ((tex[i0, j0] * (1 - fx) + tex[i0, j1] * fx) * (1 - fy)
            + (tex[i1, j0] * (1 - fx) + tex[i1, j1] * fx) * fy)


def reference_samples(case: str, data: AcceptanceData, g):
    """Per-sample weighted colour and weight of the reference (numerator, denominator)."""
    uv = g.uv
    if case in ("tabulated", "procedural"):
        c = noise_colormap(_bilerp(data.noise, uv)[..., 0])
        return c, np.ones(c.shape[:-1])
    if case == "height":
        from scipy.special import log_ndtr

        x = _bilerp(data.height, uv)[..., 0]
        wo = _upper(_local(g, g.view))
        wi = _upper(_local(g, np.broadcast_to(_LIGHT / np.linalg.norm(_LIGHT), g.view.shape)))
        lo = smith_lambda_direction(wo, data.slope_cov)
        li = smith_lambda_direction(wi, data.slope_cov)
        lp = log_ndtr(x / data.sigma_h)  # log P_h(h): eq. 2's visibility is P_h^Lambda
        vo = np.exp(lo * lp)
        return height_colormap(x) * np.exp((lo + li) * lp)[..., None], vo
    if case == "slope":
        s = _bilerp(data.slopes, uv)
        wo = _upper(_local(g, g.view))
        proj = np.maximum(0.0, wo[..., 2] - np.sum(s * wo[..., :2], -1))
        return slope_colormap(s) * proj[..., None], proj
    raise ValueError(case)


def render_case(scene, data: AcceptanceData, cases=CASES, *, n_ref: int = 32, seed: int = 0,
                rows_per_chunk: int = 2):
    """Images ``{case: {method: (H, W, 3)}}`` for methods filtered, naive, reference, plus the
    pixel mask (all reference samples hit, view and light above the surface) and the median
    footprint in texels (major axis)."""
    from prefilter.render.camera import gbuffer, gbuffer_at, pixel_positions

    cam = scene.camera
    h, w = cam.height, cam.width
    g = gbuffer(scene)
    flat = g.reshape(-1)
    out = {c: {} for c in cases}
    for c in cases:
        for m in ("filtered", "naive"):
            img = np.zeros((h * w, 3))
            img[flat.hit] = shade_pixels(c, m, data, flat.select(flat.hit))
            out[c][m] = img.reshape(h, w, 3)
    # the reference: n_ref x n_ref jittered samples per pixel
    k = n_ref
    grid = np.stack(np.meshgrid(np.arange(k), np.arange(k)), -1).reshape(-1, 2)
    num = {c: np.zeros((h, w, 3)) for c in cases}
    den = {c: np.zeros((h, w)) for c in cases}
    all_hit = np.ones((h, w), bool)
    centres = pixel_positions(cam)
    for r0 in range(0, h, rows_per_chunk):
        rows = slice(r0, min(h, r0 + rows_per_chunk))
        rng = np.random.default_rng([seed, r0])
        nr = rows.stop - rows.start
        jit = (grid[None, None] + rng.random((nr, w, k * k, 2))) / k - 0.5
        gs = gbuffer_at(scene, centres[rows][:, :, None, :] + jit)
        all_hit[rows] = gs.hit.all(-1)
        for c in cases:
            cn, cd = reference_samples(c, data, gs)
            cn = np.where(gs.hit[..., None], cn, 0.0)
            cd = np.where(gs.hit, cd, 0.0)
            num[c][rows] = cn.sum(-2)
            den[c][rows] = cd.sum(-1)
    for c in cases:
        out[c]["reference"] = num[c] / np.maximum(den[c], 1e-300)[..., None]
    light = _LIGHT / np.linalg.norm(_LIGHT)
    vz = np.sum(g.view * g.normal, -1)
    lz = np.sum(light * g.normal, -1)
    mask = g.hit & all_hit & (vz > 0.05) & (lz > 0.05)
    major, _, _ = footprint_axes(g.dudv[g.hit], (data.size, data.size))
    return out, mask, float(np.median(major))


# -- perceptual error ---------------------------------------------------------------------------

_RGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                        [0.0193, 0.1192, 0.9505]])
_WHITE = _RGB_TO_XYZ.sum(1)


def _lab(rgb):
    """CIE L*a*b* (D65) of linear sRGB colours."""
    xyz = np.clip(rgb, 0, None) @ _RGB_TO_XYZ.T / _WHITE
    e = 216 / 24389
    f = np.where(xyz > e, np.cbrt(xyz), (24389 / 27 * xyz + 16) / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], -1)


def lab_rmse(a, b, mask) -> float:
    """RMS CIE76 colour difference (Delta E*ab) over the masked pixels."""
    d = np.linalg.norm(_lab(a) - _lab(b), axis=-1)
    return float(np.sqrt(np.mean(d[mask] ** 2)))


def _flip(a, b, mask):
    try:
        from prefilter.render.metrics import flip, linear_to_srgb
    except ImportError:  # pragma: no cover
        return float("nan")
    res = flip(linear_to_srgb(np.clip(a, 0, 1)), linear_to_srgb(np.clip(b, 0, 1)), hdr=False)
    return float(np.mean(np.asarray(res.error_map)[mask]))


CONFIGS = (
    # (shape, view angle from the normal in degrees, density texels / world unit, label)
    ("plane", 0.0, 40.0, "near"), ("plane", 0.0, 3000.0, "far"),
    ("plane", 70.0, 40.0, "near"), ("plane", 70.0, 1500.0, "far"),
    ("sphere", 0.0, 10.0, "near"), ("sphere", 0.0, 900.0, "far"),
)


def run_acceptance(size: int = 48, n_ref: int = 32, seed: int = 0, configs=CONFIGS, log=None):
    """Render every configuration and case; returns a list of result rows (dicts)."""
    from prefilter.render.scene import load_scene

    data = build_data(seed=seed)
    rows = []
    for shape, view, density, label in configs:
        scene = load_scene(scene_dict(shape, view, density, size, size))
        imgs, mask, fp = render_case(scene, data, n_ref=n_ref, seed=seed)
        for case in CASES:
            ref = imgs[case]["reference"]
            row = {"shape": shape, "view_deg": view, "density": density, "distance": label,
                   "case": case, "texels_per_pixel": fp, "pixels": int(mask.sum())}
            for m in ("filtered", "naive"):
                row[f"lab_{m}"] = lab_rmse(imgs[case][m], ref, mask)
                row[f"flip_{m}"] = _flip(imgs[case][m], ref, mask)
            row["lab_ratio"] = row["lab_filtered"] / max(row["lab_naive"], 1e-12)
            row["flip_ratio"] = row["flip_filtered"] / max(row["flip_naive"], 1e-12)
            rows.append(row)
            if log:
                log(row)
    return rows


def format_rows(rows) -> str:
    """The acceptance results as a Markdown table."""
    lines = ["| shape | view | distance | texels/px | case | dE filtered | dE naive | ratio | "
             "FLIP filtered | FLIP naive | ratio |", "|" + "---|" * 11]
    for r in rows:
        lines.append(
            f"| {r['shape']} | {r['view_deg']:.0f} | {r['distance']} | "
            f"{r['texels_per_pixel']:.1f} | {r['case']} | {r['lab_filtered']:.2f} | "
            f"{r['lab_naive']:.2f} | {r['lab_ratio']:.2f} | {r['flip_filtered']:.3f} | "
            f"{r['flip_naive']:.3f} | {r['flip_ratio']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> None:  # pragma: no cover - a long run
    """``python -m prefilter.studies.colormap [SIZE] [N_REF] [OUT.json]``."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    size = int(args[0]) if args else 48
    n_ref = int(args[1]) if len(args) > 1 else 32
    rows = run_acceptance(size, n_ref)
    print(format_rows(rows))
    if len(args) > 2:
        from prefilter.fileio import save_json_atomic

        save_json_atomic(args[2], rows)


if __name__ == "__main__":  # pragma: no cover
    main()
