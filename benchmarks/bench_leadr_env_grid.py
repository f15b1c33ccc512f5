"""LEADR supplemental figure 5: the N x N Gaussian grid against importance sampling of ``P22``
for the rough specular layer under an environment map.

The supplemental (section 2.3, figure 5) compares the reconstruction filter of its uniform grid
in slope space with importance sampling of the slope distribution and finds that "for small
values of N, importance sampling is too sensitive to the random samples configuration; the
uniform grid provides better results". Here both estimate Simplified Algorithm 1
(``sum W S L / sum W S``, Schlick F = 1, no shadowing) for 1000 random views (``wo_z`` in
[0.15, 1]) and mean slopes (``N(0, 0.15^2 I)``) under ``procedural_env(128)`` (sky, sun, window
stripes), with N^2 samples each:

- grid: :func:`prefilter.leadr.shading.env_specular` (the compiled kernel; per-sample LOD from
  the Jacobian and the grid cell ``h^2 sqrt(det Sigma)``);
- importance sampling: N^2 slopes drawn from ``P22 = N(mu, Sigma)``, the same projected-area
  weights and reflection, each lookup at the LOD of the solid angle the sample stands for
  (cell ``1 / (N^2 P22(s))``: filtered importance sampling, Colbert and Krivanek 2007), over
  ``--seeds`` independent draws.

Error: relative RMSE of the luminance over the configurations against the N = 128 grid (the
reference of ``benchmarks/bench_leadr.py``'s convergence table); for importance sampling the
mean over the seeds and the worst seed. ``python benchmarks/bench_leadr_env_grid.py`` (~1 min).
"""

from __future__ import annotations

import argparse

import numpy as np

from prefilter.leadr import EnvMap, env_specular, procedural_env
from prefilter.leadr.kernels import grid_slope, micronormal, slope_cholesky

LUM = np.array([0.2126, 0.7152, 0.0722])
CASES = {"sigma 0.10": (0.1, 0.1, 0.0), "sigma 0.25": (0.25, 0.25, 0.0),
         "sigma 0.50": (0.5, 0.5, 0.0), "aniso (0.5, 0.1, r 0.5)": (0.5, 0.1, 0.5)}
GRIDS = (3, 5, 9, 17)


def configs(p: int, seed: int = 0):
    """Views ``(p, 3)`` with ``wo_z`` in [0.15, 1] and mean slopes ``(p, 2)``."""
    rng = np.random.default_rng(seed)
    cz = rng.uniform(0.15, 1.0, p)
    phi = rng.uniform(0, 2 * np.pi, p)
    sz = np.sqrt(1 - cz**2)
    return np.stack([sz * np.cos(phi), sz * np.sin(phi), cz], -1), rng.normal(scale=0.15,
                                                                            size=(p, 2))


def importance_sampled(env, wo, mu, cov, k: int, rng) -> np.ndarray:
    """Simplified Algorithm 1 with ``k`` slopes per point drawn from ``P22``, ``(P, C)``."""
    sxx, syy, sxy = cov[0, 0], cov[1, 1], cov[0, 1]
    sx, sy, r, r_ = slope_cholesky(sxx, syy, sxy)
    z = rng.standard_normal((len(wo), k, 2))
    x, y = grid_slope(mu[:, :1], mu[:, 1:], sx, sy, r, r_, z[..., 0], z[..., 1])
    m = np.stack(micronormal(x, y), -1)
    o = wo[:, None, :]
    d = np.sum(m * o, -1)
    proj = np.maximum(d, 0.0) / m[..., 2]
    wi = 2.0 * d[..., None] * m - o
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    p22 = np.exp(-0.5 * np.sum(z * z, -1)) / (2.0 * np.pi * np.sqrt(sxx * syy - sxy * sxy))
    jac = 4.0 * np.abs(d) * np.abs(m[..., 2]) ** 3
    lod = 0.5 * np.log2(np.maximum(jac / (k * p22), 1e-300) / env.texel_solid_angle)
    rad = env.lookup(wi, lod)
    return np.einsum("pk,pkc->pc", proj, rad) / np.maximum(proj.sum(1), 1e-300)[:, None]


def table(p: int = 1000, seeds: int = 8) -> list[dict]:
    """Rows ``{case, n, grid, is_mean, is_worst}`` (relative RMSE of the luminance)."""
    env = EnvMap(procedural_env(128))
    wo, mu = configs(p)
    rows = []
    for name, (sx, sy, r) in CASES.items():
        cov = np.array([[sx * sx, r * sx * sy], [r * sx * sy, sy * sy]])
        ref = env_specular(env, wo, mu, cov, 128) @ LUM

        def err(v):
            return float(np.sqrt(np.mean((v @ LUM - ref) ** 2)) / np.mean(ref))

        for n in GRIDS:
            e_is = [err(importance_sampled(env, wo, mu, cov, n * n, np.random.default_rng(s)))
                    for s in range(seeds)]
            rows.append({"case": name, "n": n, "grid": err(env_specular(env, wo, mu, cov, n)),
                         "is_mean": float(np.mean(e_is)), "is_worst": float(np.max(e_is))})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--seeds", type=int, default=8)
    a = ap.parse_args()
    print("| case | N x N | grid | importance sampling (mean of seeds) | (worst seed) |")
    print("|---|---|---|---|---|")
    for row in table(a.points, a.seeds):
        print(f"| {row['case']} | {row['n']} x {row['n']} | {100 * row['grid']:.2f}% | "
              f"{100 * row['is_mean']:.2f}% | {100 * row['is_worst']:.2f}% |", flush=True)


if __name__ == "__main__":
    main()
