"""Compiled Algorithm 1 (environment specular), one shading point per iteration, the diffuse
shadowing correction and the box filter of the moment mips.

:func:`env_specular_kernel` is :func:`prefilter.leadr.shading.env_specular`: grid micronormals,
the artificial micronormal of supplemental 3.7, the per-sample LOD from the Jacobian, trilinear
lat-long lookups (:mod:`prefilter.texture.fetch`, wrap in phi, clamp in theta) and Schlick
Fresnel; with ``shadowing`` each sample is weighted by ``G2 / G1`` (the paper's Algorithm 1).
:func:`diffuse_shadow_kernel`: the shadowing correction of the diffuse irradiance (Algorithm 2
minus Simplified Algorithm 2). :func:`box_moments_kernel`:
:func:`prefilter.leadr.render.footprint_moments`.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_inline, njit_parallel, njit_serial, prange
from prefilter.leadr.envmap import latlong_uv_jit
from prefilter.microfacet.beckmann import beckmann_lambda_jit
from prefilter.microfacet.fresnel import schlick_jit
from prefilter.texture.fetch import CLAMP_V, WRAP, trilinear_add

# -- formulas shared with the array code of prefilter.leadr.shading (arrays or scalars) --------


def slope_cholesky(sxx, syy, sxy):
    """``(sigma_x, sigma_y, r, sqrt(1 - r^2))`` of slope covariances ``[[sxx, sxy], [sxy, syy]]``:
    the Cholesky factor that Simplified Algorithm 1's grid walks (supplemental 3.4)."""
    sx = np.sqrt(sxx)
    sy = np.sqrt(syy)
    r = sxy / (sx * sy)
    return sx, sy, r, np.sqrt(np.maximum(1.0 - r * r, 0.0))


def grid_slope(mux, muy, sx, sy, r, rc, pj, pk):
    """Slope of grid node ``(p_j, p_k)``: ``x = mu_x + p_j sigma_x``,
    ``y = mu_y + (r p_j + sqrt(1 - r^2) p_k) sigma_y`` (Simplified Algorithm 1)."""
    return mux + pj * sx, muy + (pj * r + pk * rc) * sy


def micronormal(x, y):
    """Unit normal ``(-x, -y, 1) / sqrt(x^2 + y^2 + 1)`` of slope ``(x, y)`` (supplemental
    eq. 1)."""
    inv = 1.0 / np.sqrt(x * x + y * y + 1.0)
    return -x * inv, -y * inv, inv


def smith_terms(wx, wy, wz, mux, muy, sxx, syy, sxy):
    """``(w_z - mu.w_xy, w_xy^T Sigma w_xy)``: Smith's ``a = first / sqrt(2 second)`` for
    non-centred Gaussian slopes (supplemental 3.2)."""
    return wz - mux * wx - muy * wy, sxx * wx * wx + 2.0 * sxy * wx * wy + syy * wy * wy


slope_cholesky_jit = njit_inline(slope_cholesky)
grid_slope_jit = njit_inline(grid_slope)
micronormal_jit = njit_inline(micronormal)
smith_terms_jit = njit_inline(smith_terms)


@njit_inline
def _lookup(flat, offsets, heights, widths, wx, wy, wz, lod, out):  # pragma: no cover
    """``out`` = trilinear radiance of the lat-long chain in direction ``w`` at ``lod``."""
    for c in range(out.size):
        out[c] = 0.0
    u, v = latlong_uv_jit(wx, wy, wz)
    trilinear_add(flat, offsets, heights, widths, u, v, lod, out.size, 1.0, CLAMP_V, out)


@njit_serial
def _lambda_a(wx, wy, wz, mx, my, sxx, syy, sxy):  # pragma: no cover - compiled
    """Smith ``a = (w_z - mu.w_xy) / sqrt(2 w_xy^T Sigma w_xy)`` (supplemental 3.2), and
    ``Lambda(a)`` (``-1.0`` standing for +inf when ``a <= 0``: fastmath has no infinities)."""
    d, s2 = smith_terms_jit(wx, wy, wz, mx, my, sxx, syy, sxy)
    if d <= 0.0:
        return -1.0
    if s2 <= 0.0:
        return 0.0
    a = d / math.sqrt(2.0 * s2)
    if a > 5.0:
        # Lambda(5) = 1.6e-14: skip exp / erfc (most directions of a smooth surface)
        return 0.0
    return beckmann_lambda_jit(a)


@njit_serial
def _g2_over_g1(lam_o, lam_i, wiz):  # pragma: no cover - compiled
    """``1 / (1 + Lambda_i / (1 + Lambda_o))``; 0 below the geometric plane or the mesosurface,
    1 for a mesosurface facing away from the view (``Lambda_o`` infinite)."""
    if wiz <= 0.0 or lam_i < 0.0:
        return 0.0
    if lam_o < 0.0:
        return 1.0
    return 1.0 / (1.0 + lam_i / (1.0 + lam_o))


@njit_parallel
def env_specular_kernel(flat, offsets, heights, widths, texel, wo, mu, cov, rot, p, w, h, f0,
                        use_f0, lod_bias, eps, w_art, shadowing,
                        out):  # pragma: no cover - compiled
    """``out (P, C)`` for views ``wo (P, 3)``, mean slopes ``(P, 2)``, covariances ``(P, 2, 2)``,
    local-to-world ``rot (P, 3, 3)``, 1D grid ``p, w`` of spacing ``h``, Schlick ``f0 (P,)``."""
    npts = wo.shape[0]
    nc = flat.shape[1]
    n = p.size
    for q in prange(npts):
        ox, oy, oz = wo[q, 0], wo[q, 1], wo[q, 2]
        sxx, syy, sxy = cov[q, 0, 0], cov[q, 1, 1], cov[q, 0, 1]
        sx, sy, r, r_ = slope_cholesky_jit(sxx, syy, sxy)
        cell = h * h * math.sqrt(sxx * syy - sxy * sxy)
        num = np.zeros(nc)
        rad = np.empty(nc)
        den = 0.0
        lam_o = _lambda_a(ox, oy, oz, mu[q, 0], mu[q, 1], sxx, syy, sxy) if shadowing else 0.0
        for k in range(n * n + 1):
            if k < n * n:
                j, i = k // n, k % n
                x, y = grid_slope_jit(mu[q, 0], mu[q, 1], sx, sy, r, r_, p[j], p[i])
                mx, my, mz = micronormal_jit(x, y)
                wt = w[j] * w[i]
            else:
                # Artificial micronormal (supplemental 3.7).
                bx, by, bz = -mu[q, 0], -mu[q, 1], 1.0
                bn = 1.0 / math.sqrt(bx * bx + by * by + 1.0)
                bx, by, bz = bx * bn, by * bn, bz * bn
                d = (bx * ox + by * oy + bz * oz) * eps
                mx, my, mz = bx - d * ox, by - d * oy, bz - d * oz
                tn = max(math.sqrt(mx * mx + my * my + mz * mz), 1e-300)
                mx, my, mz = mx / tn, my / tn, mz / tn
                wt = w_art
            dot = mx * ox + my * oy + mz * oz
            proj = max(dot, 0.0) / (mz if k < n * n else 1.0)
            rx, ry, rz = 2 * dot * mx - ox, 2 * dot * my - oy, 2 * dot * mz - oz
            jac = 4.0 * abs(dot) * abs(mz) ** 3
            lod = 0.5 * math.log2(max(jac * cell, 1e-300) / texel) + lod_bias
            gx = rot[q, 0, 0] * rx + rot[q, 0, 1] * ry + rot[q, 0, 2] * rz
            gy = rot[q, 1, 0] * rx + rot[q, 1, 1] * ry + rot[q, 1, 2] * rz
            gz = rot[q, 2, 0] * rx + rot[q, 2, 1] * ry + rot[q, 2, 2] * rz
            _lookup(flat, offsets, heights, widths, gx, gy, gz, lod, rad)
            fr = 1.0
            if use_f0:
                fr = schlick_jit(f0[q], min(max(dot, 0.0), 1.0))
            ws = wt * proj
            den += ws
            if shadowing and k < n * n:
                # (the artificial micronormal stays unshadowed: it only exists so that a
                # footprint that sees nothing is not black)
                fr *= _g2_over_g1(lam_o, _lambda_a(rx, ry, rz, mu[q, 0], mu[q, 1], sxx, syy, sxy),
                                  rz)
            for c in range(nc):
                num[c] += ws * fr * rad[c]
        for c in range(nc):
            if den > 1e-300:
                out[q, c] = num[c] / den
            else:
                out[q, c] = rad[c] * fr
    return out


@njit_parallel
def diffuse_shadow_kernel(dirs, lw, wo, mu, cov, rot, p, w, out):  # pragma: no cover - compiled
    """``out (P, C)`` = ``-(1 / pi) sum W S E_lost(m) / sum W S`` with
    ``E_lost(m) = sum_d lw_d <m, d>+ (1 - G2 / G1(wo, d))``: the irradiance that self-shadowing
    removes, by quadrature over directions ``dirs (D, 3)`` (map coordinates) with weights
    ``lw (D, C)`` = radiance x solid angle; ``rot (P, 3, 3)`` local -> map."""
    npts = wo.shape[0]
    nc = lw.shape[1]
    n = p.size
    nd = dirs.shape[0]
    for q in prange(npts):
        ox, oy, oz = wo[q, 0], wo[q, 1], wo[q, 2]
        sxx, syy, sxy = cov[q, 0, 0], cov[q, 1, 1], cov[q, 0, 1]
        sx, sy, r, r_ = slope_cholesky_jit(sxx, syy, sxy)
        lam_o = _lambda_a(ox, oy, oz, mu[q, 0], mu[q, 1], sxx, syy, sxy)
        # the grid's micronormals, their weights W S and the steepest slope |s|
        gm = np.empty((n * n, 3))
        gw = np.empty(n * n)
        den = 0.0
        steep = 0.0
        for j in range(n):
            for i in range(n):
                x, y = grid_slope_jit(mu[q, 0], mu[q, 1], sx, sy, r, r_, p[j], p[i])
                mx, my, mz = micronormal_jit(x, y)
                k = j * n + i
                gm[k, 0], gm[k, 1], gm[k, 2] = mx, my, mz
                gw[k] = w[j] * w[i] * max(mx * ox + my * oy + mz * oz, 0.0) / mz
                den += gw[k]
                steep = max(steep, math.sqrt(x * x + y * y))
        num = np.zeros(nc)
        for k in range(nd):
            dx = rot[q, 0, 0] * dirs[k, 0] + rot[q, 1, 0] * dirs[k, 1] + rot[q, 2, 0] * dirs[k, 2]
            dy = rot[q, 0, 1] * dirs[k, 0] + rot[q, 1, 1] * dirs[k, 1] + rot[q, 2, 1] * dirs[k, 2]
            dz = rot[q, 0, 2] * dirs[k, 0] + rot[q, 1, 2] * dirs[k, 1] + rot[q, 2, 2] * dirs[k, 2]
            if dz <= 0.0:
                # blocked by the height field itself (lost = 1), but only the grid's steepest
                # micronormals see below the horizon: m.d > 0 needs |d_z| < |s| |d_xy|
                if -dz >= steep * math.sqrt(dx * dx + dy * dy):
                    continue
                lost = 1.0
            else:
                lost = 1.0 - _g2_over_g1(
                    lam_o, _lambda_a(dx, dy, dz, mu[q, 0], mu[q, 1], sxx, syy, sxy), dz)
                if lost <= 0.0:
                    continue
            acc = 0.0
            for g in range(n * n):
                c_ = gm[g, 0] * dx + gm[g, 1] * dy + gm[g, 2] * dz
                if c_ > 0.0:
                    acc += gw[g] * c_
            if acc > 0.0:
                for c in range(nc):
                    num[c] += acc * lost * lw[k, c]
        for c in range(nc):
            out[q, c] = -num[c] / (den * math.pi) if den > 1e-300 else 0.0
    return out


@njit_parallel
def box_moments_kernel(flat, offsets, heights, widths, uv, dudv, major, max_taps,
                       out):  # pragma: no cover - compiled
    """``out (N, C)``: mean of ``T x T`` trilinear taps over each footprint parallelogram
    ``uv + dudv @ o``, ``T = clip(ceil(major / 2), 1, max_taps)``, each at
    ``lod = log2(max(major / T, 1))`` (:func:`prefilter.leadr.render.footprint_moments`)."""
    npts = uv.shape[0]
    nc = flat.shape[1]
    for q in prange(npts):
        t = int(math.ceil(major[q] / 2.0))
        t = min(max(t, 1), max_taps)
        lod = math.log2(max(major[q] / t, 1.0))
        acc = np.zeros(nc)
        for i in range(t):
            oy = (i + 0.5) / t - 0.5
            for j in range(t):
                ox = (j + 0.5) / t - 0.5
                u = uv[q, 0] + dudv[q, 0, 0] * ox + dudv[q, 0, 1] * oy
                v = uv[q, 1] + dudv[q, 1, 0] * ox + dudv[q, 1, 1] * oy
                trilinear_add(flat, offsets, heights, widths, u, v, lod, nc, 1.0, WRAP, acc)
        for c in range(nc):
            out[q, c] = acc[c] / (t * t)
    return out
