"""Throughput of the LTC polygon integral: 1e6 random quads with random matrices M.

Prints integrals per second for the public entries (``polygon_integral`` inverts M per polygon,
``polygon_integral_minv`` takes M^-1) and for the pure NumPy reference, and the
NumPy-reference / Numba time ratio measured in this run. Best of ``REPEAT`` timings each; the first
call (JIT compilation or cache load) is excluded.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

from prefilter.sphere.polygon import (clamped_cosine_integral, polygon_integral,
                                      polygon_integral_minv)

# the NumPy twin the tests check the kernel against
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "ltc"))
from ltc_numpy import polygon_integral_numpy  # noqa: E402

N = 1_000_000
REPEAT = 5


def random_quads(rng: np.random.Generator, n: int) -> np.ndarray:
    """Planar rectangles ``(n, 4, 3)`` around the shading point, many straddling the horizon."""
    centre = rng.normal(size=(n, 3)) * np.array([2.0, 2.0, 1.0]) + np.array([0.0, 0.0, 1.0])
    a = rng.normal(size=(n, 3))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b = np.cross(a, rng.normal(size=(n, 3)))
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    ha, hb = rng.uniform(0.1, 1.5, size=(2, n, 1))
    corners = [centre - ha * a - hb * b, centre + ha * a - hb * b,
               centre + ha * a + hb * b, centre - ha * a + hb * b]
    return np.stack(corners, axis=1)


def best_time(f, repeat: int = REPEAT) -> tuple[float, float]:
    """Best wall-clock and best process CPU time (all threads) over ``repeat`` calls, seconds.

    CPU time is reported too because the machine is shared: wall time then depends on the load,
    CPU time much less (it still rises with contention for caches and hyperthreads)."""
    f()  # compile / load the cache
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        f()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def main() -> None:
    rng = np.random.default_rng(1)
    V = random_quads(rng, N)
    M = np.eye(3) + 0.4 * rng.normal(size=(N, 3, 3))
    M_inv = np.linalg.inv(M)
    print(f"{N} random quads, random M; numba threads = {numba.get_num_threads()}")

    t_m = best_time(lambda: polygon_integral(M, V))
    t_minv = best_time(lambda: polygon_integral_minv(M_inv, V))
    t_cos = best_time(lambda: clamped_cosine_integral(V))
    numba.set_num_threads(1)
    t_one = best_time(lambda: polygon_integral_minv(M_inv, V))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    t_np = best_time(lambda: polygon_integral_numpy(M_inv, V), repeat=2)
    diff = np.max(np.abs(polygon_integral_minv(M_inv, V) - polygon_integral_numpy(M_inv, V)))
    rows = [("polygon_integral(M, P)", t_m), ("polygon_integral_minv(M_inv, P)", t_minv),
            ("clamped_cosine_integral(P)", t_cos), ("polygon_integral_minv, 1 thread", t_one),
            ("NumPy reference (M_inv)", t_np)]
    print(f"  {'':34s} {'wall':>9s} {'cpu':>9s}   wall throughput")
    for name, (w, c) in rows:
        print(f"  {name:34s} {w * 1e3:6.1f} ms {c * 1e3:6.1f} ms   "
              f"{N / w / 1e6:6.2f} M integrals/s")
    print(f"  ratio NumPy reference / Numba (polygon_integral_minv): "
          f"wall {t_np[0] / t_minv[0]:.1f}x, cpu {t_np[1] / t_minv[1]:.1f}x")
    print(f"  max |Numba - NumPy| = {diff:.2e}")
    print(f"  load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cpus")


if __name__ == "__main__":
    main()
