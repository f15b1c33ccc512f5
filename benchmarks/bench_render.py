"""Renderer throughput and the reference's convergence (``make bench``; no assertions).

Prints, in the same run:
* primary-ray + G-buffer throughput (Mpixel/s) for a 512 x 512 view of a plane, for the Numba
  kernel ("new") and the NumPy implementation the tests check it against ("old");
* ``ltc`` shading throughput (Mpixel/s, one quad light): the shader alone over flat arrays, and the
  whole ``ltc`` method (G-buffer + mip lookups + shading) on a normal-mapped plane;
  wall time (best of 3) and the CPU time of the process (less sensitive to other jobs' load);
* ``reference`` cost per sample (microseconds, one quad light, normal-mapped plane);
* with ``--convergence``: RMSE of ``reference`` vs a high-spp image for spp = 4 .. 1024 on a small
  normal-mapped scene, and the fitted slope of log RMSE vs log spp (docs/reference.md).

Thread count follows NUMBA_NUM_THREADS (the polygon kernel); NumPy parts are single-threaded.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from prefilter.ltc.shading import shade_ltc
from prefilter.render import gbuffer, load_scene
from prefilter.render.camera import generate_rays
from prefilter.render.driver import render, surface_attributes

# the NumPy twin the tests check the kernels against
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "render"))
from gbuffer_numpy import intersect_numpy  # noqa: E402


def scene(width: int, height: int, normal_map: bool = True) -> dict:
    material = {"alpha": 0.2, "base_color": [0.2, 0.15, 0.1], "f0": [0.9, 0.6, 0.5]}
    if normal_map:
        material["normal_map"] = {"procedural": "gaussian", "size": 256, "seed": 1,
                                  "rms_slope": 0.25, "corr_length": 3}
    return {
        "camera": {"origin": [0, 1.2, 3], "target": [0, 0, -1], "fov": 50,
                   "width": width, "height": height},
        "objects": [{"type": "plane", "center": [0, 0, -5], "normal": [0, 1, 0],
                     "size": [20, 20], "uv_scale": [10, 10], "material": material}],
        "lights": [{"type": "quad", "radiance": [4, 4, 4],
                    "vertices": [[-1.5, 0.3, -4], [1.5, 0.3, -4], [1.5, 2.0, -4],
                                 [-1.5, 2.0, -4]]}],
    }


def best_of(fn, repeats: int = 3) -> float:
    return best_of_cpu(fn, repeats)[0]


def best_of_cpu(fn, repeats: int = 3) -> tuple[float, float]:
    """Best wall time and best process CPU time (all threads) of ``repeats`` calls."""
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus)


def line(what: str, n: int, new, old=None) -> None:
    t, c = new
    msg = f"{what:38s} new {n / t / 1e6:6.3f} Mpixel/s ({t * 1e3:6.1f} ms, cpu {c * 1e3:6.1f} ms)"
    if old is not None:
        msg += f"   old {n / old[0] / 1e6:6.3f} Mpixel/s ({old[0] * 1e3:6.1f} ms)"
        msg += f"   x{old[0] / t:.1f}"
    print(msg)


def bench_throughput() -> None:
    s = load_scene(scene(512, 512))
    npix = 512 * 512
    gbuffer(s)  # warm-up (and JIT)
    new = best_of_cpu(lambda: gbuffer(s))
    old = best_of_cpu(lambda: intersect_numpy(s, generate_rays(s.camera)))
    line("primary rays + G-buffer, 512x512 plane", npix, new, old)

    try:
        from prefilter.ltc.table import GGXTable

        table = GGXTable.load()
    except Exception as exc:  # noqa: BLE001 - the table is another part's output
        print(f"ltc: skipped ({exc})")
        table = None
    if table is not None:
        g = gbuffer(s).reshape(-1)
        g = g.select(g.hit)
        a = surface_attributes(s, g, filtered=True)
        args = (g.position, a["t"], a["b"], a["n"], g.view, np.full(len(g.hit), 0.2),
                a["base_color"], a["f0"], s.light_set(), table)
        shade_ltc(*args)
        n = len(g.hit)
        line(f"ltc shader alone ({n} points)", n, best_of_cpu(lambda: shade_ltc(*args)))
        render(s, "ltc", table=table)
        line("ltc end to end, 512x512", npix, best_of_cpu(lambda: render(s, "ltc", table=table)))

    s2 = load_scene(scene(128, 128))
    spp = 16
    render(s2, "reference", spp=1)
    t = best_of(lambda: render(s2, "reference", spp=spp), repeats=2)
    n = 128 * 128 * spp
    print(f"reference, 1 quad light, 128x128x{spp} spp:  {t / n * 1e6:7.3f} us/sample  "
          f"({n / t / 1e6:.3f} Msample/s, {t:.2f} s)")


def bench_convergence(width: int = 32, height: int = 24, truth_spp: int = 4096) -> None:
    s = load_scene(scene(width, height))
    t0 = time.perf_counter()
    truth = render(s, "reference", spp=truth_spp, seed=12345)
    print(f"convergence: {width}x{height} normal-mapped plane, truth = {truth_spp} spp "
          f"({time.perf_counter() - t0:.1f} s)")
    spps = [4, 16, 64, 256, 1024]
    rows = []
    for n in spps:
        img = render(s, "reference", spp=n, seed=1)
        rows.append(np.sqrt(np.mean((img - truth) ** 2)))
    rmse = np.array(rows)
    # The truth has noise too: E|img - truth|^2 = sigma^2 (1/n + 1/N). Remove the second term,
    # estimating sigma^2 from the lowest spp.
    sigma2 = rmse[0] ** 2 / (1 / spps[0] + 1 / truth_spp)
    corrected = np.sqrt(np.maximum(rmse**2 - sigma2 / truth_spp, 0.0))
    print("   spp      RMSE   RMSE (truth noise removed)   RMSE * sqrt(spp)")
    for n, e, c in zip(spps, rmse, corrected):
        print(f"  {n:5d}  {e:.3e}   {c:.3e}                   {c * np.sqrt(n):.3e}")
    slope = np.polyfit(np.log(spps), np.log(rmse), 1)[0]
    slope_c = np.polyfit(np.log(spps), np.log(corrected), 1)[0]
    print(f"  fitted slope of log RMSE vs log spp: {slope:.3f} (raw), {slope_c:.3f} (corrected)")
    print(f"  mean radiance of the truth: {truth.mean():.4f}")


if __name__ == "__main__":
    bench_throughput()
    if "--convergence" in sys.argv[1:]:
        bench_convergence()
