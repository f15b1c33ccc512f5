"""Colour-map filtering cost: filtered / naive shading time for the texture (a), procedural noise
(b) and height (c) cases, and the slope case (d) for information, on a 512 x 512 G-buffer of a
plane seen at 60 degrees, textured at two densities (magnified and minified footprints; the
percentiles of the footprint sizes are printed).

(a)-(c) run the compiled per-pixel kernels of ``prefilter.colormap.kernels`` (the shader-like
path; tested equal to the NumPy path); (d) the NumPy path, for information. Both methods of a case
do everything their shading needs from the G-buffer on (anisotropic footprint lookups, Smith
Lambda for the shadowing factor of (c)); the naive method reads a one-channel mean mip and row 0
of the table, the filtered one the moments mip and the 2D table. Single-threaded
(``numba.set_num_threads(1)``), best of 7 runs of each, interleaved, after a warm-up call
(compilation), timed twice: wall clock, then process CPU time (``time.process_time``), which on a
shared, loaded machine leaves out the time the process waits for a core (wall-clock ratios there
swing by +-0.1 from run to run). The ratio is the reportable number (the target is <= 1.3 for
(a)-(c)). No assertions.
"""

from __future__ import annotations

import time

import numba
import numpy as np

from prefilter.studies.colormap import build_data, scene_dict
from prefilter.colormap.kernels import PackedChain, shade_height, shade_noise, shade_texture
from prefilter.colormap.slope import filter_slope
from prefilter.colormap.texture import footprint_stats
from prefilter.render import gbuffer, load_scene
from prefilter.texture.mip import MipChain, footprint_axes

SIZE = 512
LIGHT = np.array([0.4, 0.8, 0.45]) / np.linalg.norm([0.4, 0.8, 0.45])


def _local(g, w):
    return np.stack([np.sum(w * g.tangent, -1), np.sum(w * g.bitangent, -1),
                     np.sum(w * g.normal, -1)], -1)


def main() -> None:
    # one thread: on a shared machine, parallel timings mostly measure the other processes
    numba.set_num_threads(1)
    data = build_data()
    for density in (300.0, 3000.0):
        run(data, density)


def run(data, density) -> None:
    scene = load_scene(scene_dict("plane", 60.0, density, SIZE, SIZE))
    g = gbuffer(scene).reshape(-1)
    g = g.select(g.hit)
    uv, dudv = g.uv, g.dudv
    wo = _local(g, g.view)
    wi = _local(g, np.broadcast_to(LIGHT, g.view.shape))
    ok = (wo[:, 2] > 0.01) & (wi[:, 2] > 0.01)
    uv, dudv, wo, wi = uv[ok], dudv[ok], wo[ok], wi[ok]
    t_noise, t_height = data.noise_table, data.height_table
    mean_noise, moments_noise = PackedChain(data.noise_mip), PackedChain(data.noise_moments)
    mean_height = PackedChain(MipChain(data.height))
    moments_height = PackedChain(data.height_moments)

    def a_naive():
        return shade_texture(t_noise, mean_noise, uv, dudv, filtered=False)

    def a_filtered():
        return shade_texture(t_noise, moments_noise, uv, dudv)

    def b_naive():
        return shade_noise(t_noise, mean_noise, data.noise_std, uv, dudv, filtered=False)

    def b_filtered():
        return shade_noise(t_noise, mean_noise, data.noise_std, uv, dudv)

    def c_naive():
        return shade_height(t_height, mean_height, uv, dudv, wo, wi, data.slope_cov,
                            filtered=False)

    def c_filtered():
        return shade_height(t_height, moments_height, uv, dudv, wo, wi, data.slope_cov)

    slope_mean_mip = MipChain(data.slopes)

    def d_naive():
        return data.slope_table.naive(slope_mean_mip.lookup_footprint(uv, dudv,
                                                                      anisotropic=True))

    def d_filtered():
        mean, cov = footprint_stats(data.slope_moments, uv, dudv, anisotropic=True)
        return filter_slope(data.slope_table, wo, mean, cov)

    major, minor, _ = footprint_axes(dudv, (data.size, data.size))
    q = np.percentile(major, [5, 50, 95])
    print(f"{uv.shape[0]} shaded pixels (plane at 60 degrees, {SIZE}x{SIZE}, {density:g} texels "
          f"per unit): footprint major axis 5/50/95% = {q[0]:.2g} / {q[1]:.2g} / {q[2]:.2g} "
          f"texels")
    for name, naive, filt in (("(a) tabulated", a_naive, a_filtered),
                              ("(b) procedural", b_naive, b_filtered),
                              ("(c) height", c_naive, c_filtered),
                              ("(d) slope", d_naive, d_filtered)):
        tn, tf = _best(naive, filt, time.perf_counter)
        cn, cf = _best(naive, filt, time.process_time)
        print(f"{name:15s} naive {tn * 1e3:7.1f} ms  filtered {tf * 1e3:7.1f} ms  "
              f"ratio {tf / tn:4.2f}  | cpu: naive {cn * 1e3:7.1f} ms  filtered "
              f"{cf * 1e3:7.1f} ms  ratio {cf / cn:4.2f}")


def _best(naive, filt, clock, runs: int = 7):
    """Best of ``runs`` interleaved calls of each on ``clock``."""
    tn, tf = float("inf"), float("inf")
    naive(), filt()  # compile / warm caches
    for _ in range(runs):
        t0 = clock()
        naive()
        tn = min(tn, clock() - t0)
        t0 = clock()
        filt()
        tf = min(tf, clock() - t0)
    return tn, tf


if __name__ == "__main__":
    main()
