"""Render methods for glinty materials: ``glints``, ``glints-direct``, ``glints-reference``.

A material's ``normal_map`` is the microstructure; its NDF over each pixel footprint replaces the
GGX lobe (``alpha_x``/``alpha_y`` are ignored; the intrinsic roughness is the bake's). Shading is
in the *geometric* frame (``x`` = tangent = ``+u``, ``y`` = ``+v``): the normal map enters only
through the NDF. Diffuse: Lambert with ``base_color``. Point and directional lights only (quad and
environment lights are rejected).

Footprints: the pixel is a Gaussian of std ``PIXEL_SIGMA`` pixels; through the texel-space
Jacobian ``J = diag(W, H) dudv`` it becomes an ellipse, approximated by the isotropic Gaussian of
the same area, ``sigma_p = PIXEL_SIGMA sqrt(|det J|)`` texels, centred at ``(u W, v H)``; with
``spp > 1`` stratified sub-pixel samples each gets ``sigma_p / sqrt(spp)`` (the paper's "pixel
footprint divided by the sample count").

* ``glints``: the compressed NDF (:func:`prefilter.glints.brdf.glint_ndf`: point query, trilinear
  over the pyramid, direct P-NDF below the finest level). The normal map is baked on first use
  with :data:`BAKE_SETTINGS` and cached on disk (``$PREFILTER_GLINTS_CACHE`` or
  ``~/.cache/prefilter/glints``) under the SHA-1 of the normals and the settings.
* ``glints-direct``: the direct P-NDF of Yan et al. 2016 for every footprint (cost ~ its area).
* ``glints-reference``: supersampling of the footprint with the full-resolution normal map and the
  intrinsic roughness: ``spp`` sub-pixel positions drawn from the same pixel Gaussian, each shaded
  with the P-NDF of a point (``sigma_p = 0``: Yan's partition of unity of per-texel linearised
  normals, each blurred by the intrinsic roughness). Its mean converges to the Gaussian-footprint
  integral, which ``glints-direct`` evaluates in closed form (up to the isotropic approximation of
  the footprint and the linearisation of ``uv`` across the pixel).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
from tqdm import tqdm

from prefilter.errors import PrefilterError
from prefilter.glints.brdf import GlintSurface, glint_brdf_cos, surface
from prefilter.glints.pndf import DEFAULT_ROUGHNESS, as_normal_map

PIXEL_SIGMA = 0.5
#: Bake settings of the render cache. The intrinsic roughness is twice Yan et al.'s 0.005 so that
#: the NDF pixels (pitch 1/128) resolve the intrinsic lobe: with 0.005 a pixel is 1.6 std wide
#: and the pixel averages differ from the direct P-NDF's point values at every sharp glint.
BAKE_SETTINGS = dict(rank=16, ndf_res=128, block=16, support=0.5, stride0=4,
                     intrinsic_roughness=2 * DEFAULT_ROUGHNESS, n_iter_max=50, seed=0)
_SURFACES: dict = {}


def cache_dir() -> Path:
    d = os.environ.get("PREFILTER_GLINTS_CACHE")
    return Path(d) if d else Path.home() / ".cache" / "prefilter" / "glints"


def baked_surface(normal_map, *, direct: bool = False, settings: dict | None = None,
                  progress: bool = False) -> GlintSurface:
    """The :class:`GlintSurface` of a normal map: baked once (disk cache), then kept in memory.

    ``direct=True`` returns a surface without the compressed map (``glints-direct``).
    """
    from prefilter.glints.bake import bake
    from prefilter.glints.store import load

    nm = as_normal_map(normal_map)
    st = dict(BAKE_SETTINGS, **(settings or {}))
    H, W = nm.shape[:2]
    st.setdefault("cell", min(64, H, W))
    digest = hashlib.sha1(np.ascontiguousarray(nm, dtype=np.float64).tobytes()).hexdigest()
    key = hashlib.sha1(json.dumps(st, sort_keys=True).encode()).hexdigest()[:12]
    mem = (digest, "direct" if direct else key)
    if mem not in _SURFACES:
        if direct:
            _SURFACES[mem] = surface(None, nm, intrinsic_roughness=st["intrinsic_roughness"])
        else:
            path = cache_dir() / f"{digest[:20]}-{key}.npz"
            if not path.exists():
                path.parent.mkdir(parents=True, exist_ok=True)
                bake(nm, path, progress=progress, **st)
            _SURFACES[mem] = surface(load(path), nm, check=False)
    return _SURFACES[mem]


def footprints(g, shape, spp: int = 1):
    """Footprint centres ``(N, 2)`` and stds ``(N,)`` in texels of flat G-buffer samples ``g``
    on a ``shape = (H, W)`` map (see the module docstring)."""
    H, W = shape
    center = g.uv * np.array([W, H], dtype=np.float64)
    J = g.dudv * np.array([W, H], dtype=np.float64)[:, None]
    det = np.abs(J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0])
    return center, PIXEL_SIGMA * np.sqrt(det / spp)


def _local(w, t, b, n):
    return np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)


def shade_glints(scene, g, *, mode: str, spp: int = 1, sigma=None) -> np.ndarray:
    """Radiance ``(N, 3)`` of hit samples ``g`` under the scene's point and directional lights.

    ``mode``: ``"compressed"`` or ``"direct"``; ``sigma`` overrides the footprint stds (the
    reference passes zeros)."""
    lights = scene.light_set()
    flip = np.where(np.sum(g.view * g.normal, -1) < 0.0, -1.0, 1.0)[:, None]
    t, b, n = g.tangent, g.bitangent * flip, g.normal * flip
    wo = _local(g.view, t, b, n)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    incoming = []
    for pl in lights.points:
        d = pl.position - g.position
        d2 = np.maximum(np.sum(d * d, -1), 1e-300)
        incoming.append((d / np.sqrt(d2)[:, None], pl.intensity / d2[:, None]))
    for dl in lights.directionals:
        incoming.append((np.broadcast_to(-dl.direction, g.position.shape), dl.irradiance))
    out = np.zeros((len(wo), 3))
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        if mat.normal_map is None:
            raise PrefilterError(f"objects[{int(k)}].material.normal_map: the glints methods "
                                 "expected a normal map (the microstructure), got none")
        surf = baked_surface(mat.normal_map.load(), direct=(mode == "direct"))
        c, sp = footprints(g.select(m), surf.shape, spp)
        if sigma is not None:
            sp = np.broadcast_to(sigma, m.shape)[m]
        base = np.asarray(mat.base_color, dtype=np.float64)
        for w, e in incoming:
            wi = _local(w[m], t[m], b[m], n[m])
            wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
            spec = glint_brdf_cos(surf, c, sp, wo[m], wi, mat.f0)
            diff = base / np.pi * np.maximum(wi[:, 2], 0.0)[:, None]
            out[m] += (spec + diff) * e[m] if np.ndim(e) == 2 else (spec + diff) * e
    return out


def _check_lights(scene, name):
    if any(light.type in ("quad", "environment") for light in scene.lights):
        raise PrefilterError(f"method {name!r}: expected only point and directional lights")


def _render(scene, settings, mode, name):
    from prefilter.render.pipeline import render_samples

    _check_lights(scene, name)
    spp = settings.spp
    return render_samples(scene, settings,
                          lambda g, _u: shade_glints(scene, g, mode=mode, spp=spp),
                          stratified=spp > 1, desc=name)


def render_glints(scene, settings) -> np.ndarray:
    """The ``glints`` method: compressed footprint NDF (point query) under point lights."""
    return _render(scene, settings, "compressed", "glints")


def render_glints_direct(scene, settings) -> np.ndarray:
    """The ``glints-direct`` method: direct P-NDF of every footprint (Yan et al. 2016)."""
    return _render(scene, settings, "direct", "glints-direct")


def render_glints_reference(scene, settings) -> np.ndarray:
    """The ``glints-reference`` method: ``spp`` sub-pixel samples from the pixel Gaussian, each
    shaded with the point P-NDF of the full-resolution normal map (``sigma_p = 0``)."""
    from prefilter.render.camera import gbuffer_at
    from prefilter.render.pipeline import row_rng

    _check_lights(scene, "glints-reference")
    cam = scene.camera
    h, w, s = cam.height, cam.width, settings.spp
    rows_per_chunk = max(1, settings.chunk_samples // (w * s))
    image = np.zeros((h, w, 3))
    with tqdm(total=h, desc="glints-reference", unit="row", delay=1.0, leave=False,
              disable=not settings.progress) as bar:
        for r0 in range(0, h, rows_per_chunk):
            rows = range(r0, min(h, r0 + rows_per_chunk))
            offs = np.stack([row_rng(settings.seed, y).normal(0.0, PIXEL_SIGMA, (w, s, 2))
                             for y in rows])
            xy = offs + 0.5 + np.asarray(settings.jitter, dtype=np.float64)
            xy[..., 0] += np.arange(w)[None, :, None]
            xy[..., 1] += np.asarray(rows, dtype=np.float64)[:, None, None]
            g = gbuffer_at(scene, xy).reshape(-1)
            rad = np.zeros((g.hit.size, 3))
            if np.any(g.hit):
                rad[g.hit] = shade_glints(scene, g.select(g.hit), mode="direct", sigma=0.0)
            image[r0:r0 + len(rows)] = rad.reshape(len(rows), w, s, 3).mean(axis=2)
            bar.update(len(rows))
    return image.astype(np.float32)


# ------------------------------------------------------------------------------- measurements


def measurement_scene(distance: float, kind: str = "flakes", size: int = 128, width: int = 64,
                      height: int = 48) -> dict:
    """A glinty plane seen from ``distance`` (camera and point light scaled together, so the
    image is the same apart from the footprint size, ~proportional to the distance)."""
    d = float(distance)
    return {"camera": {"origin": [0, 0.6 * d, d], "target": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 30, "width": width, "height": height},
            "objects": [{"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0],
                         "tangent": [1, 0, 0], "size": [40 * d, 40 * d],
                         "uv_scale": [160 * d] * 2,
                         "material": {"alpha": 0.1, "base_color": [0, 0, 0],
                                      "f0": [0.9, 0.9, 0.9],
                                      "normal_map": {"procedural": kind, "size": size,
                                                     "seed": 1}}}],
            "lights": [{"type": "point", "position": [0, 0.6 * d, -d],
                        "intensity": [5 * d * d] * 3}]}


def measure(distances=(0.5, 2.0, 8.0), kind: str = "flakes", size: int = 128,
            ref_spp: int = 64) -> list[dict]:
    """Frame times (best of 2) of ``glints`` and ``glints-direct`` at each distance in one run,
    FLIP between them and against ``glints-reference`` (``ref_spp``)."""
    import time

    from prefilter.render.metrics import flip
    from prefilter.render.pipeline import render
    from prefilter.render.scene import load_scene

    rows = []
    for d in distances:
        sc = load_scene(measurement_scene(d, kind, size))
        render(sc, "glints")  # bake / compile outside the timing
        t = {}
        img = {}
        for m in ("glints", "glints-direct"):
            best = np.inf
            for _ in range(2 if m == "glints" else 1):
                t0 = time.perf_counter()
                img[m] = render(sc, m)
                best = min(best, time.perf_counter() - t0)
            t[m] = best
        img["ref"] = render(sc, "glints-reference", spp=ref_spp)
        from prefilter.render.camera import gbuffer_at

        xy = np.stack(np.meshgrid(np.arange(sc.camera.width) + 0.5,
                                  np.arange(sc.camera.height) + 0.5), -1)
        g = gbuffer_at(sc, xy).reshape(-1)
        _, sp = footprints(g.select(g.hit), (size, size))
        rows.append(dict(distance=d, sigma_p_median=float(np.median(sp)),
                         t_glints=t["glints"], t_direct=t["glints-direct"],
                         speedup=t["glints-direct"] / t["glints"],
                         flip_glints_direct=float(flip(img["glints"], img["glints-direct"]).mean),
                         flip_glints_ref=float(flip(img["glints"], img["ref"]).mean),
                         flip_direct_ref=float(flip(img["glints-direct"], img["ref"]).mean),
                         mean_ratio=float(img["glints"].mean() / img["glints-direct"].mean())))
        print(json.dumps(rows[-1]), flush=True)
    return rows


def ndf_errors(kinds=("gaussian", "brushed", "flakes", "scratches"), size: int = 64,
               sigmas=(4.0, 8.0, 16.0), n: int = 6, seed: int = 0) -> list[dict]:
    """Relative L2 error of NDF images against the direct P-NDF images (pixel averages) for
    ``n`` random footprints per size: the compressed query, and a smooth lobe (a Gaussian NDF of
    ``s`` with the footprint's mean and covariance: a plain microfacet model with matched
    moments)."""
    from prefilter.glints import pndf_image, point
    from prefilter.texture.procedural import normal_map

    R, S = BAKE_SETTINGS["ndf_res"], BAKE_SETTINGS["support"]
    sr, h = BAKE_SETTINGS["intrinsic_roughness"], 2 * BAKE_SETTINGS["support"] / R
    x = (np.arange(R) + 0.5) * h - S
    X, Y = np.meshgrid(x, x)
    grid = np.stack([X, Y], -1)
    rng = np.random.default_rng(seed)
    rows = []
    for kind in kinds:
        nm = normal_map(kind, size=size, seed=1)
        surf = baked_surface(nm)
        row = {"map": kind, "bake_error": surf.gm.header["summary"]["rel_l2_error"]}
        for sp in sigmas:
            c = rng.uniform(0, size, (n, 2))
            ref = pndf_image(nm, c, sp, R, S, sr)
            got = point(surf.gm, c[:, None, None], sp, grid[None])
            w = ref * h * h
            m = w.sum((1, 2))
            mx, my = (w * X).sum((1, 2)) / m, (w * Y).sum((1, 2)) / m
            dx, dy = X - mx[:, None, None], Y - my[:, None, None]
            cxx, cyy = (w * dx * dx).sum((1, 2)) / m, (w * dy * dy).sum((1, 2)) / m
            cxy = (w * dx * dy).sum((1, 2)) / m
            det = (cxx * cyy - cxy**2)[:, None, None]
            q = (cyy[:, None, None] * dx * dx - 2 * cxy[:, None, None] * dx * dy
                 + cxx[:, None, None] * dy * dy) / det
            smooth = m[:, None, None] * np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(det))

            def err(a):
                d = np.linalg.norm((a - ref).reshape(n, -1), axis=1)
                return float(np.mean(d / np.linalg.norm(ref.reshape(n, -1), axis=1)))

            row[f"sigma_p={sp:g}"] = {"glints": err(got), "smooth": err(smooth)}
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


if __name__ == "__main__":  # python -m prefilter.glints.render [frames KIND | ndf]
    import sys

    if len(sys.argv) > 1 and sys.argv[1] == "ndf":
        ndf_errors()
    else:
        measure(kind=sys.argv[2] if len(sys.argv) > 2 else "flakes")
