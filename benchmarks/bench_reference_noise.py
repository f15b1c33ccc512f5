"""Noise of the ``reference`` method at equal time, against the estimator it replaced
(``make bench``; no assertions).

Two scenes under one quad light (the demo's showcase view): (a) a flat GGX plane, (b) the same
plane normal-mapped. For each, in the same run:

* ground truth: the new estimator at ``--truth`` sample pairs per pixel (and its own error, from a
  second seed, so the floor it puts under the new estimator's error is known);
* the old estimator (below, kept only as this comparison's baseline: stratified sub-pixel
  positions, one independent uniform MIS light/BRDF pair per position, area-sampled light,
  5 uniforms per pair) at ``--spp`` samples per pixel;
* the new ``reference`` at powers of two, then at the sample count whose time matches the old
  one's (the largest of up to four tries, steered from either side, that is not more than 2 %
  slower); every time is the best of 3 calls, the old and the new estimator's calls
  alternating (other jobs on a shared machine slow both alike);
* relative MSE of each (:func:`prefilter.render.metrics.relmse`), the equal-time ratio
  ``relMSE_old / relMSE_new`` and the efficiency ratio ``relMSE_old t_old / (relMSE_new t_new)``;
* the share of pixel values the method clamps at 0 (the control variate can give negative
  estimates at low sample counts);
* the new estimator without its control variate (``control=none``) at the same sample count,
  to show what the control variate takes away;
* bias check: both estimators at ``--bias-spp`` (4096) samples per pixel and ``--bias-seeds``
  seeds each, the ratio of their image means per channel (should be 1 within 0.1 %) and the
  standard error of the old estimator's mean (from its seeds), on a smaller image of the same
  view.

Usage: ``python benchmarks/bench_reference_noise.py [--size 48x32] [--spp 64] [--truth 8192]
[--bias-spp 4096] [--bias-size 32x24] [--bias-seeds 3]``.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from prefilter.jit import njit_parallel, njit_serial, prange
from prefilter.report.demo import showcase_scene
from prefilter.render.metrics import relmse
from prefilter.render.methods import RenderSettings
from prefilter.render.driver import render, render_samples, surface_attributes
from prefilter.render.reference import render_reference
from prefilter.render.scene import load_scene
from prefilter.render.shading import local_view, shade_delta_lights


# --------------------------------------------------------------------- the baseline estimator

OLD_DIMS_PER_QUAD = 5


@njit_serial
def old_lambda(ax, ay, x, y, z):
    a2 = ((ax * x) ** 2 + (ay * y) ** 2) / max(z * z, 1e-300)
    return a2 / (1.0 + math.sqrt(1.0 + a2)) / 2.0


@njit_serial
def old_ggx_d(ax, ay, x, y, z):
    if z <= 0.0:
        return 0.0
    t = (x / ax) ** 2 + (y / ay) ** 2 + z * z
    return 1.0 / (math.pi * ax * ay * t * t)


@njit_serial
def old_brdf_pdf(wox, woy, woz, wix, wiy, wiz, ax, ay, base, f0, p_spec, f_out):
    """Writes the cosine-weighted BRDF (rgb) into ``f_out``; returns the mixture pdf."""
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if hn > 1e-12:
        hx, hy, hz = hx / hn, hy / hn, hz / hn
    else:
        hx, hy, hz = 0.0, 0.0, 1.0
    lam_o = old_lambda(ax, ay, wox, woy, woz)
    d = old_ggx_d(ax, ay, hx, hy, hz)
    spec = 0.0
    if woz > 0.0 and wiz > 0.0:
        spec = d / (1.0 + lam_o + old_lambda(ax, ay, wix, wiy, wiz)) / (4.0 * woz)
    c = min(max(wix * hx + wiy * hy + wiz * hz, 0.0), 1.0)
    c5 = (1.0 - c) ** 5
    cos_i = max(wiz, 0.0)
    for k in range(3):
        f_out[k] = base[k] / math.pi * cos_i + (f0[k] + (1.0 - f0[k]) * c5) * spec
    # Density of a reflected visible normal (pdf_reflect) and of the cosine lobe.
    doth = wox * hx + woy * hy + woz * hz
    p_s = 0.0
    if doth > 1e-12 and woz > 0.0:
        p_s = (d * doth / (1.0 + lam_o) / woz) / (4.0 * doth)
    return p_spec * p_s + (1.0 - p_spec) * cos_i / math.pi


@njit_parallel
def old_quad_kernel(pos, ts, bs, ns, wo, ax, ay, base, f0, verts, normal, area, u, out, hit):
    """``out[i, 0]`` / ``out[i, 1]``: the light- and BRDF-sample terms (rgb, untextured);
    ``hit[i, 0]`` / ``hit[i, 1]``: their points on the light (for the light texture)."""
    n = pos.shape[0]
    tri1 = 0.5 * math.sqrt(
        ((verts[1, 1] - verts[0, 1]) * (verts[2, 2] - verts[0, 2])
         - (verts[1, 2] - verts[0, 2]) * (verts[2, 1] - verts[0, 1])) ** 2
        + ((verts[1, 2] - verts[0, 2]) * (verts[2, 0] - verts[0, 0])
           - (verts[1, 0] - verts[0, 0]) * (verts[2, 2] - verts[0, 2])) ** 2
        + ((verts[1, 0] - verts[0, 0]) * (verts[2, 1] - verts[0, 1])
           - (verts[1, 1] - verts[0, 1]) * (verts[2, 0] - verts[0, 0])) ** 2)
    p1 = tri1 / area
    for i in prange(n):
        f = np.empty(3)
        wox, woy, woz = wo[i, 0], wo[i, 1], wo[i, 2]
        axi, ayi = ax[i], ay[i]
        # Lobe selection probability (specular_probability).
        c5 = (1.0 - min(max(woz, 0.0), 1.0)) ** 5
        s = 0.0
        dsum = 0.0
        for k in range(3):
            s += (f0[i, k] + (1.0 - f0[i, k]) * c5) / 3.0
            dsum += base[i, k] / 3.0
        tot = s + dsum
        p_spec = min(max(s / tot, 0.05), 1.0) if tot > 0.0 else 0.5
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        # -- light sample: uniform on the area (sample_quad_area) --
        u0 = u[i, 0]
        if u0 < p1:
            u0 = u0 / p1
            b_i, c_i = 1, 2
        else:
            u0 = (u0 - p1) / (1.0 - p1) if p1 < 1.0 else 0.0
            b_i, c_i = 2, 3
        u0 = min(max(u0, 0.0), 1.0)
        su = math.sqrt(u0)
        b0 = 1.0 - su
        b1 = u[i, 1] * su
        b2 = 1.0 - b0 - b1
        dx = verts[0, 0] + b1 * (verts[c_i, 0] - verts[0, 0]) + b2 * (verts[b_i, 0] - verts[0, 0])
        dy = verts[0, 1] + b1 * (verts[c_i, 1] - verts[0, 1]) + b2 * (verts[b_i, 1] - verts[0, 1])
        dz = verts[0, 2] + b1 * (verts[c_i, 2] - verts[0, 2]) + b2 * (verts[b_i, 2] - verts[0, 2])
        hit[i, 0, 0], hit[i, 0, 1], hit[i, 0, 2] = dx, dy, dz
        dx -= pos[i, 0]
        dy -= pos[i, 1]
        dz -= pos[i, 2]
        dist2 = dx * dx + dy * dy + dz * dz
        dist = math.sqrt(dist2)
        if dist > 1e-12:
            dx, dy, dz = dx / dist, dy / dist, dz / dist
            cos_l = -(dx * normal[0] + dy * normal[1] + dz * normal[2])
            if cos_l > 1e-12:
                pl = dist2 / (area * cos_l)
                lx = dx * ts[i, 0] + dy * ts[i, 1] + dz * ts[i, 2]
                ly = dx * bs[i, 0] + dy * bs[i, 1] + dz * bs[i, 2]
                lz = dx * ns[i, 0] + dy * ns[i, 1] + dz * ns[i, 2]
                ln = math.sqrt(lx * lx + ly * ly + lz * lz)
                lx, ly, lz = lx / ln, ly / ln, lz / ln
                pb = old_brdf_pdf(wox, woy, woz, lx, ly, lz, axi, ayi, base[i], f0[i], p_spec, f)
                den = pl + pb
                if den > 0.0:
                    acc0 += f[0] / den
                    acc1 += f[1] / den
                    acc2 += f[2] / den
        out[i, 0, 0] = acc0
        out[i, 0, 1] = acc1
        out[i, 0, 2] = acc2
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        hit[i, 1, 0], hit[i, 1, 1], hit[i, 1, 2] = pos[i, 0], pos[i, 1], pos[i, 2]
        # -- BRDF sample: GGX visible normal (Heitz 2018) reflected, or cosine --
        if u[i, 4] < p_spec:
            vx, vy, vz = axi * wox, ayi * woy, woz
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            vx, vy, vz = vx / vn, vy / vn, vz / vn
            lensq = vx * vx + vy * vy
            if lensq > 1e-14:
                inv = 1.0 / math.sqrt(lensq)
                t1x, t1y, t1z = -vy * inv, vx * inv, 0.0
            else:
                t1x, t1y, t1z = 1.0, 0.0, 0.0
            t2x = vy * t1z - vz * t1y
            t2y = vz * t1x - vx * t1z
            t2z = vx * t1y - vy * t1x
            r = math.sqrt(u[i, 2])
            phi = 2.0 * math.pi * u[i, 3]
            q1 = r * math.cos(phi)
            q2 = r * math.sin(phi)
            sw = 0.5 * (1.0 + vz)
            q2 = (1.0 - sw) * math.sqrt(max(0.0, 1.0 - q1 * q1)) + sw * q2
            q3 = math.sqrt(max(0.0, 1.0 - q1 * q1 - q2 * q2))
            mx = axi * (q1 * t1x + q2 * t2x + q3 * vx)
            my = ayi * (q1 * t1y + q2 * t2y + q3 * vy)
            mz = max(1e-12, q1 * t1z + q2 * t2z + q3 * vz)
            mn = math.sqrt(mx * mx + my * my + mz * mz)
            mx, my, mz = mx / mn, my / mn, mz / mn
            dot = wox * mx + woy * my + woz * mz
            bx, by, bz = 2.0 * dot * mx - wox, 2.0 * dot * my - woy, 2.0 * dot * mz - woz
        else:
            # Shirley-Chiu concentric disk lifted to the hemisphere (cosine_hemisphere).
            a = 2.0 * u[i, 2] - 1.0
            b = 2.0 * u[i, 3] - 1.0
            if a == 0.0 and b == 0.0:
                rr, ph = 0.0, 0.0
            elif abs(a) > abs(b):
                rr, ph = a, (math.pi / 4.0) * b / a
            else:
                rr, ph = b, math.pi / 2.0 - (math.pi / 4.0) * a / b
            bx, by = rr * math.cos(ph), rr * math.sin(ph)
            bz = math.sqrt(max(0.0, 1.0 - bx * bx - by * by))
        # World direction and its hit on the front of the quad (quad_light_pdf).
        wx = bx * ts[i, 0] + by * bs[i, 0] + bz * ns[i, 0]
        wy = bx * ts[i, 1] + by * bs[i, 1] + bz * ns[i, 1]
        wz = bx * ts[i, 2] + by * bs[i, 2] + bz * ns[i, 2]
        cos_l = -(wx * normal[0] + wy * normal[1] + wz * normal[2])
        if cos_l > 1e-12:
            t = ((verts[0, 0] - pos[i, 0]) * normal[0] + (verts[0, 1] - pos[i, 1]) * normal[1]
                 + (verts[0, 2] - pos[i, 2]) * normal[2]) / (-cos_l)
            if t > 0.0:
                hx = pos[i, 0] + t * wx
                hy = pos[i, 1] + t * wy
                hz = pos[i, 2] + t * wz
                inside = True
                for k in range(4):
                    k1 = (k + 1) % 4
                    ex = verts[k1, 0] - verts[k, 0]
                    ey = verts[k1, 1] - verts[k, 1]
                    ez = verts[k1, 2] - verts[k, 2]
                    px = hx - verts[k, 0]
                    py = hy - verts[k, 1]
                    pz = hz - verts[k, 2]
                    cr = ((ey * pz - ez * py) * normal[0] + (ez * px - ex * pz) * normal[1]
                          + (ex * py - ey * px) * normal[2])
                    if cr < 0.0:
                        inside = False
                if inside:
                    hit[i, 1, 0], hit[i, 1, 1], hit[i, 1, 2] = hx, hy, hz
                    plb = t * t / (area * cos_l)
                    pb = old_brdf_pdf(wox, woy, woz, bx, by, bz, axi, ayi, base[i], f0[i], p_spec,
                                   f)
                    den = plb + pb
                    if den > 0.0:
                        acc0 += f[0] / den
                        acc1 += f[1] / den
                        acc2 += f[2] / den
        out[i, 1, 0] = acc0
        out[i, 1, 1] = acc1
        out[i, 1, 2] = acc2



def render_old(scene, spp: int, seed: int) -> np.ndarray:
    """The baseline: stratified sub-pixel positions, one uniform-random MIS pair per position
    and quad light (untextured quads only)."""
    lights = scene.light_set()
    settings = RenderSettings(spp=spp, seed=seed)
    q = len(lights.quads)

    def shade(g, u):
        a = surface_attributes(scene, g, filtered=False)
        n = len(g.position)
        ts, bs, ns = a["t"], a["b"], a["n"]
        wo = local_view(g.view, ts, bs, ns)
        out = shade_delta_lights(g.position, ts, bs, ns, wo, a["alpha_x"], a["alpha_y"],
                                 a["base_color"], a["f0"], lights)
        for k, ql in enumerate(lights.quads):
            uq = u.reshape(n, q, OLD_DIMS_PER_QUAD)
            res = np.empty((n, 2, 3))
            hit = np.empty((n, 2, 3))
            old_quad_kernel(g.position, ts, bs, ns, wo, a["alpha_x"], a["alpha_y"],
                            a["base_color"], a["f0"], ql.vertices, ql.normal, float(ql.area),
                            np.ascontiguousarray(uq[:, k]), res, hit)
            out += (res[:, 0] + res[:, 1]) * ql.radiance
        return out

    return render_samples(scene, settings, shade, random_dims=q * OLD_DIMS_PER_QUAD,
                          stratified=True, desc="reference-old")


# ------------------------------------------------------------------------------ measurements


def timed(fn, other=None, repeats: int = 3):
    """``(result, best wall time, other's best wall time)`` of ``repeats`` calls of ``fn``, each
    followed by a call of ``other`` (if given), so both see the same load."""
    best, best_o, out = math.inf, math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        if other is not None:
            t0 = time.perf_counter()
            other()
            best_o = min(best_o, time.perf_counter() - t0)
    return out, best, best_o


def scenes(width: int, height: int) -> dict:
    flat = showcase_scene(1.0, width, height)
    del flat["objects"][0]["material"]["normal_map"]
    return {"flat GGX plane": flat, "normal-mapped plane": showcase_scene(1.0, width, height)}


def new(scene, spp, seed, control="ltc"):
    return np.asarray(render(scene, "reference", spp=spp, seed=seed,
                             params={"control": control}), dtype=np.float64)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="48x32")
    ap.add_argument("--bias-size", default="32x24")
    ap.add_argument("--spp", type=int, default=64, help="the old estimator's samples per pixel")
    ap.add_argument("--truth", type=int, default=8192, help="ground-truth pairs per pixel")
    ap.add_argument("--bias-spp", type=int, default=4096)
    ap.add_argument("--bias-seeds", type=int, default=3)
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    bw, bh = (int(v) for v in args.bias_size.split("x"))
    print(f"reference noise at equal time: {w}x{h}, one quad light, old at {args.spp} spp, "
          f"truth {args.truth} pairs/pixel")
    for name, sc in scenes(w, h).items():
        scene = load_scene(sc)
        # warm-up: compile both paths at both batch sizes
        render_old(scene, args.spp, 0)
        new(scene, args.spp, 0)
        truth = new(scene, args.truth, 1000)
        truth2 = new(scene, args.truth // 4, 2000)
        floor = relmse(truth2, truth) / 5.0  # error of the truth: var(t4) + var(t) = 5 var(t)
        old, t_old, _ = timed(lambda: render_old(scene, args.spp, 1))
        e_old = relmse(old, truth)
        rows = []
        spp = 4
        while True:
            img, t, t_o = timed(lambda: new(scene, spp, 1), lambda: render_old(scene, args.spp, 1))
            t_old = min(t_old, t_o)
            rows.append((spp, t, relmse(img, truth)))
            if t > t_old or spp >= args.truth // 4:
                break
            spp *= 2
        # the sample count whose time matches the old estimator's (time ~ linear in spp),
        # a multiple of 4 (whole runs of pairs), then shrunk until it is not slower
        below = [r for r in rows if r[1] <= t_old] or rows[:1]
        s0, t0 = below[-1][:2]
        spp_eq = max(4, int(s0 * t_old / t0) // 4 * 4)
        # steer the sample count towards the old estimator's time from either side (timings
        # on a shared machine jump), keeping the largest count that is not slower (within 2 %)
        best = None
        for _ in range(4):
            img, t, t_o = timed(lambda: new(scene, spp_eq, 1),
                                lambda: render_old(scene, args.spp, 1))
            t_old = min(t_old, t_o)
            if t <= t_old * 1.02 and (best is None or spp_eq > best[0]):
                best = (spp_eq, t, img)
            if abs(t / t_old - 1.0) <= 0.02 or (spp_eq <= 4 and t > t_old):
                break
            spp_eq = max(4, int(spp_eq * t_old / t * 0.99) // 4 * 4)
        if best is None:
            best = (spp_eq, t, img)
        spp_eq, t_new, img = best
        spp_new, e_new = spp_eq, relmse(img, truth)
        print(f"  {name}:")
        print(f"    old  {args.spp:6d} spp  {t_old:6.3f} s  relMSE {e_old:.3e}")
        for s, t, e in rows:
            print(f"    new  {s:6d} spp  {t:6.3f} s  relMSE {e:.3e}")
        print(f"    truth's own relMSE (floor under the new estimator's): {floor:.1e}")
        print(f"    new  {spp_new:6d} spp  {t_new:6.3f} s  relMSE {e_new:.3e}  (equal time)")
        raw = np.asarray(render_reference(scene, RenderSettings(spp=spp_new, seed=1),
                                          clamp=False))
        print(f"    values the method clamps at 0 at {spp_new} spp: {np.mean(raw < 0) * 100:.3f} % "
              f"(smallest {raw.min():.3g}; relMSE unclamped {relmse(raw, truth):.3e})")
        plain, t_plain, _ = timed(lambda: new(scene, spp_new, 1, "none"))
        print(f"    new without the control variate (control=none) at {spp_new} spp: "
              f"{t_plain:.3f} s, relMSE {relmse(plain, truth):.3e}")
        print(f"    equal-time relMSE ratio (old / new at {spp_new} spp, "
              f"{t_new:.3f} s vs {t_old:.3f} s): {e_old / e_new:.1f}x; efficiency "
              f"(relMSE x time) ratio {e_old * t_old / (e_new * t_new):.1f}x")
        # bias: both at bias_spp on a smaller image of the same view (the old one is slow)
        small = load_scene(scenes(bw, bh)[name])
        seeds = range(7, 7 + args.bias_seeds)
        a = np.array([render_old(small, args.bias_spp, s).reshape(-1, 3).mean(0) for s in seeds])
        b = np.array([new(small, args.bias_spp, s).reshape(-1, 3).mean(0) for s in seeds])
        ratio = b.mean(0) / a.mean(0)
        se = a.std(0, ddof=1) / np.sqrt(len(a)) / a.mean(0) if len(a) > 1 else np.zeros(3)
        print(f"    mean ratio new / old at {args.bias_spp} spp ({bw}x{bh}, {len(a)} seeds): "
              + " ".join(f"{r:.5f}" for r in ratio)
              + f"  (max deviation {np.max(np.abs(ratio - 1)) * 100:.3f} %; the old mean's "
              f"standard error {np.max(se) * 100:.3f} %)")


if __name__ == "__main__":
    main()
