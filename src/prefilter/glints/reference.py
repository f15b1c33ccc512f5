"""Deterministic references for glint shading under quad and environment lights.

Under area lights the ``glints-direct`` method is a Monte Carlo estimate (MIS for quads, SG sampling
for environments), so a 1-spp frame carries noise as large as the compression error it is meant to
judge. This module evaluates the *expectations* of those estimators, with the direct P-NDF
(Yan et al. 2016), by quadrature instead of sampling:

* quad lights, :func:`quad_integral`: ``int_quad f cos L dw`` by the midpoint rule on a grid of
  the quad whose cells map to at most ``ds_max`` in projected half vectors ``s`` (every P-NDF
  element is a Gaussian of std >= the intrinsic roughness, so ``ds_max = 0.4 sigma_r`` resolves
  it; the light's edges are cell edges);
* environment lights given as spherical Gaussians, :func:`environment_integral`: with
  ``dw_i = 4 (w_i.h) ds / h_z`` the specular integral is ``int D_p(s) K(s) ds``,
  ``K = F G L(w_i) (w_i.h) / (w_o_z h_z)``, evaluated element by element (each element's 2D
  Gaussian against a bilinear table of the smooth ``K``, :func:`pndf_integral`). With ``blur`` it
  is the expectation of ``glints``' *prefiltered* SG estimator with the direct NDF: that estimator
  replaces ``D(h)`` by its mean over the square ``h_xy +- r``, and
  ``int K (B_r * D) = int D (B_r * K)`` for the symmetric box ``B_r``.

:func:`render_converged` renders a scene with these (specular plus the quad's Lambert term by
the polygon formula, as the render methods do), on the render methods' own G-buffer samples and
footprints (:mod:`prefilter.glints.render`).
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_inline, njit_parallel, prange, serial
from prefilter.validation import as_float_array
from prefilter.errors import PrefilterError
# public kernels of pndf.py, under the short local names the kernels below use
from prefilter.glints.pndf import (SIGMA_H, TRUNCATION, element_moments as _element,
                                   footprint_window as _footprint, wide_limit2 as _wide2)

#: Quad lights: the largest cell of the quadrature grid in ``s`` (0.4 of the render's intrinsic
#: roughness 0.01) and the most cells per side.
DS_MAX = 0.004
MAX_CELLS = 96
#: Environment lights: nodes per axis of the table of ``K`` over ``s in [-1, 1]^2`` (spacing
#: 0.021; ``K`` varies on the scale of the SG lobes, ~0.13 in ``s`` for the render's fit).
ENV_RES = 97
#: Element cubature along a wide principal axis: node spacing in ``s`` (the table is bilinear
#: at 0.021 and smooth on ~0.1).
LINE_STEP = 0.025


def _surface_arrays(surf):
    from prefilter.glints.brdf import as_surface

    surf = as_surface(surf)
    if surf.normal_map is None:
        raise PrefilterError("surf: the direct P-NDF needs the normal map (a surface built with "
                             "normal_map=...)")
    s_el, J = surf.elements_
    return surf, s_el, J


def _footprints(center, sigma_p):
    c = as_float_array(center, "center", ndim_min=2, last_dim=2)
    if c.ndim != 2:
        raise PrefilterError(f"center: expected (N, 2), got {c.shape}")
    sp = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), c.shape[:1])
    if np.any(sp < 0) or np.any(sp > 1e6):
        raise PrefilterError("sigma_p: expected footprint stds in texels in [0, 1e6]")
    return np.ascontiguousarray(c[:, 0]), np.ascontiguousarray(c[:, 1]), np.ascontiguousarray(sp)


# ------------------------------------------------------------------------------------ kernels


@njit_parallel
def _pndf_csr(s_el, J, cx, cy, sp, qx, qy, off, sr, sh, trunc, lim2, out):
    """``out[j]`` = P-NDF of footprint ``q`` at ``(qx, qy)[j]`` for ``j`` in ``off[q]:off[q+1]``:
    one pass over the footprint's texels for all its points (elements that cannot reach the
    points' bounding box are skipped; same cut-off as ``pndf._pndf_points``)."""
    H, W = s_el.shape[0], s_el.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    cut = 8.0 * trunc * trunc
    for q in prange(cx.shape[0]):
        j0, j1 = off[q], off[q + 1]
        if j1 <= j0:
            continue
        bx0, bx1, by0, by1 = qx[j0], qx[j0], qy[j0], qy[j0]
        for j in range(j0, j1):
            out[j] = 0.0
            bx0 = min(bx0, qx[j])
            bx1 = max(bx1, qx[j])
            by0 = min(by0, qy[j])
            by1 = max(by1, qy[j])
        x0, x1, y0, y1, f, var, tot2, wide = _footprint(cx[q], cy[q], sp[q], sh2, trunc, H, W,
                                                        lim2)
        wsum = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            r = y % H
            for x in range(x0, x1 + 1):
                dx = cx[q] - (x + 0.5)
                c = x % W
                w = 1.0 if wide else math.exp(-(dx * dx + dy * dy) / (2.0 * tot2))
                wsum += w
                mx, my, a, b, d = _element(s_el, J, r, c, dx, dy, f, var)
                a += sr2
                d += sr2
                # the ellipse {quad < cut} spans sqrt(cut * var) along each axis
                rx = math.sqrt(cut * a)
                ry = math.sqrt(cut * d)
                if mx + rx < bx0 or mx - rx > bx1 or my + ry < by0 or my - ry > by1:
                    continue
                det = a * d - b * b
                norm = w / (2.0 * math.pi * math.sqrt(det))
                for j in range(j0, j1):
                    ex = qx[j] - mx
                    ey = qy[j] - my
                    quad = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
                    if quad < cut:
                        out[j] += norm * math.exp(-0.5 * quad)
        for j in range(j0, j1):
            out[j] /= wsum


@njit_inline
def _bilinear_add(T, q, lo, h, px, py, wgt, acc):  # pragma: no cover - compiled
    """``acc += wgt * T[q]`` interpolated bilinearly at ``(px, py)`` (zero off the grid)."""
    R = T.shape[1]
    gx = (px - lo) / h
    gy = (py - lo) / h
    if gx < 0.0 or gy < 0.0 or gx > R - 1 or gy > R - 1:
        return
    ix = min(int(gx), R - 2)
    iy = min(int(gy), R - 2)
    fx = gx - ix
    fy = gy - iy
    w00 = wgt * (1.0 - fx) * (1.0 - fy)
    w01 = wgt * fx * (1.0 - fy)
    w10 = wgt * (1.0 - fx) * fy
    w11 = wgt * fx * fy
    for ch in range(T.shape[3]):
        acc[ch] += (w00 * T[q, iy, ix, ch] + w01 * T[q, iy, ix + 1, ch]
                    + w10 * T[q, iy + 1, ix, ch] + w11 * T[q, iy + 1, ix + 1, ch])


@njit_parallel
def _pndf_table(s_el, J, cx, cy, sp, T, lo, h, step, sr, sh, trunc, lim2, out):
    """``out[q] = int D_p(s) T[q](s) ds`` with ``T[q]`` bilinear on the node grid
    ``lo + i h``: per element, a 3-point Gauss-Hermite rule along its minor axis times a
    3-point rule (or, when wider than ``step``, nodes ``<= step`` apart over +-4 std) along its
    major axis (exact for the element's mass, mean and covariance)."""
    H, W = s_el.shape[0], s_el.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    g3 = math.sqrt(3.0)
    for q in prange(cx.shape[0]):
        acc = np.zeros(out.shape[1])
        x0, x1, y0, y1, f, var, tot2, wide = _footprint(cx[q], cy[q], sp[q], sh2, trunc, H, W,
                                                        lim2)
        wsum = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            r = y % H
            for x in range(x0, x1 + 1):
                dx = cx[q] - (x + 0.5)
                c = x % W
                w = 1.0 if wide else math.exp(-(dx * dx + dy * dy) / (2.0 * tot2))
                wsum += w
                mx, my, a, b, d = _element(s_el, J, r, c, dx, dy, f, var)
                half = 0.5 * (a + d)
                dif = math.sqrt(0.25 * (a - d) * (a - d) + b * b)
                s1 = math.sqrt(half + dif + sr2)
                s2 = math.sqrt(max(half - dif, 0.0) + sr2)
                if dif > 1e-300:
                    if a >= d:
                        vx, vy = half + dif - d, b
                    else:
                        vx, vy = b, half + dif - a
                    vn = math.sqrt(vx * vx + vy * vy)
                    vx /= vn
                    vy /= vn
                else:
                    vx, vy = 1.0, 0.0
                n1 = 3 if s1 <= step else int(math.ceil(8.0 * s1 / step)) + 1
                norm1 = 0.0
                if n1 > 3:
                    for k in range(n1):
                        tk = -4.0 + 8.0 * k / (n1 - 1)
                        norm1 += math.exp(-0.5 * tk * tk)
                for k in range(n1):
                    if n1 == 3:
                        t1 = (k - 1) * g3
                        w1 = 2.0 / 3.0 if k == 1 else 1.0 / 6.0
                    else:
                        t1 = -4.0 + 8.0 * k / (n1 - 1)
                        w1 = math.exp(-0.5 * t1 * t1) / norm1
                    for m in range(3):
                        t2 = (m - 1) * g3
                        w2 = 2.0 / 3.0 if m == 1 else 1.0 / 6.0
                        px = mx + s1 * t1 * vx - s2 * t2 * vy
                        py = my + s1 * t1 * vy + s2 * t2 * vx
                        _bilinear_add(T, q, lo, h, px, py, w * w1 * w2, acc)
        for ch in range(out.shape[1]):
            out[q, ch] = acc[ch] / wsum


# ------------------------------------------------------------------------------- P-NDF sums


def pndf_multi(surf, center, sigma_p, s, offsets) -> np.ndarray:
    """Direct P-NDF of footprint ``q`` at its own half vectors ``s[offsets[q]:offsets[q+1]]``.

    Yan et al. 2016 (the P-NDF of a Gaussian footprint), as :func:`prefilter.glints.pndf.pndf`
    but one pass over the footprint's texels for all its points.

    Parameters
    ----------
    surf : GlintSurface with its normal map (its ``intrinsic_roughness`` is used).
    center : (N, 2) texels; sigma_p : (N,) texels; s : (P, 2); offsets : (N + 1,) non-decreasing
        ints from 0 to P.

    Returns
    -------
    (P,) densities w.r.t. ``s``.
    """
    surf, s_el, J = _surface_arrays(surf)
    cx, cy, sp = _footprints(center, sigma_p)
    q = as_float_array(s, "s", ndim_min=2, last_dim=2)
    off = np.asarray(offsets)
    if (off.shape != (len(sp) + 1,) or not np.issubdtype(off.dtype, np.integer) or off[0] != 0
            or off[-1] != len(q) or np.any(np.diff(off) < 0)):
        raise PrefilterError(f"offsets: expected {len(sp) + 1} non-decreasing ints from 0 to "
                             f"{len(q)}, got shape {off.shape}")
    out = np.zeros(len(q))
    serial(_pndf_csr, len(q))(s_el, J, cx, cy, sp, np.ascontiguousarray(q[:, 0]),
                              np.ascontiguousarray(q[:, 1]), off.astype(np.int64),
                              surf.intrinsic_roughness, SIGMA_H, TRUNCATION, _wide2(s_el), out)
    return out


def pndf_integral(surf, center, sigma_p, table, lo: float, h: float, *,
                  step: float = LINE_STEP) -> np.ndarray:
    """``int D_p(s) T_q(s) ds`` per footprint for tables ``T_q`` bilinear on a node grid.

    Yan et al. 2016's P-NDF is a mixture of 2D Gaussians (one per texel); each is integrated
    against ``T_q`` by a Gauss-Hermite product rule along its principal axes.

    Parameters
    ----------
    table : (N, R, R, C) node values, row index along ``s_y``: node ``(i, j)`` at
        ``s = (lo + j h, lo + i h)``; ``T = 0`` off the grid. ``T`` should be smooth on the
        scale of the elements (std >= the intrinsic roughness), e.g. an environment's BRDF and
        radiance factor; a light's sharp edge needs :func:`pndf_multi` instead.

    Returns
    -------
    (N, C).
    """
    surf, s_el, J = _surface_arrays(surf)
    cx, cy, sp = _footprints(center, sigma_p)
    T = as_float_array(table, "table", ndim_min=4)
    if T.ndim != 4 or T.shape[0] != len(sp) or T.shape[1] != T.shape[2] or T.shape[1] < 2:
        raise PrefilterError(f"table: expected ({len(sp)}, R, R, C) with R >= 2, got {T.shape}")
    if not (h > 0 and step > 0):
        raise PrefilterError(f"h, step: expected > 0, got {h}, {step}")
    out = np.zeros((len(sp), T.shape[3]))
    serial(_pndf_table, len(sp) * 64)(s_el, J, cx, cy, sp, np.ascontiguousarray(T), float(lo),
                                      float(h), float(step), surf.intrinsic_roughness, SIGMA_H,
                                      TRUNCATION, _wide2(s_el), out)
    return out


# ------------------------------------------------------------------------------------ lights


def _smooth_factor(wo, wi, f0):
    """``F G / (4 wo_z)`` (..., C), the half vector and the validity mask: ``f cos = k D``."""
    from prefilter.glints.brdf import vcavity_g2
    from prefilter.microfacet.fresnel import schlick

    h = wo + wi
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    ok = (wo[..., 2] > 0) & (wi[..., 2] > 0) & (h[..., 2] > 0)
    k = np.where(ok, vcavity_g2(wo, wi, h) / (4.0 * np.where(ok, wo[..., 2], 1.0)), 0.0)
    return k[..., None] * schlick(f0, np.sum(wi * h, -1)[..., None]), h, ok


def quad_integral(surf, center, sigma_p, wo, corners, radiance, f0=1.0, *,
                  ds_max: float = DS_MAX, max_cells: int = MAX_CELLS,
                  ndf: str = "direct") -> np.ndarray:
    """Specular ``int_quad f cos L dw`` of a quad light with the direct P-NDF, by quadrature.

    Glints paper eq. 1 (microfacet BRDF with the footprint's P-NDF) integrated over the light:
    midpoint rule on an ``n_a x n_b`` grid of the quad's bilinear parametrisation, ``n`` per
    footprint such that a cell spans at most ``ds_max`` in ``s`` along each side (capped at
    ``max_cells``); cell solid angle ``|dP/da x dP/db| da db cos(theta_l) / |P|^2``.

    Parameters
    ----------
    surf : GlintSurface with its normal map; center (N, 2), sigma_p (N,): footprints.
    wo : (N, 3) local view directions; corners : (N, 4, 3) quad corners relative to the shading
        point in the local frame, counter-clockwise seen from the lit side.
    radiance : (3,); f0 : (3,) or scalar.
    ndf : ``"direct"`` (the direct P-NDF, :func:`pndf_multi`) or ``"surface"`` (the surface's own
        evaluation, :func:`prefilter.glints.brdf.glint_ndf`: the compressed NDF of ``glints``'
        point queries), for separating compression from a light estimator's error.

    Returns
    -------
    (N, 3).
    """
    if ndf not in ("direct", "surface"):
        raise PrefilterError(f"ndf: expected 'direct' or 'surface', got {ndf!r}")
    wo = as_float_array(wo, "wo", ndim_min=2, last_dim=3)
    V = as_float_array(corners, "corners", ndim_min=3)
    N = len(wo)
    if V.shape != (N, 4, 3):
        raise PrefilterError(f"corners: expected ({N}, 4, 3), got {V.shape}")
    f0 = np.atleast_1d(np.asarray(f0, dtype=np.float64))
    L = np.asarray(radiance, dtype=np.float64)
    # cells per side from the half-vector spread along each pair of opposite edges
    d = V / np.linalg.norm(V, axis=-1, keepdims=True)
    hc = d + wo[:, None, :]
    hc /= np.maximum(np.linalg.norm(hc, axis=-1, keepdims=True), 1e-300)
    sc = hc[..., :2]
    ea = np.maximum(np.abs(sc[:, 1] - sc[:, 0]).max(-1), np.abs(sc[:, 2] - sc[:, 3]).max(-1))
    eb = np.maximum(np.abs(sc[:, 3] - sc[:, 0]).max(-1), np.abs(sc[:, 2] - sc[:, 1]).max(-1))
    na = np.clip(np.ceil(ea / ds_max), 2, max_cells).astype(np.int64)
    nb = np.clip(np.ceil(eb / ds_max), 2, max_cells).astype(np.int64)
    normal = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    front = np.sum(normal * V[:, 0], -1) < 0.0
    cnt = np.where(front, na * nb, 0)
    center = as_float_array(center, "center", ndim_min=2, last_dim=2)
    sigma_p = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), (N,))
    out = np.zeros((N, 3))
    # chunks of at most ~2^20 quadrature points
    step = max(1, (1 << 20) // max(int(cnt.max()), 1))
    for c0 in range(0, N, step):
        sl = slice(c0, c0 + step)
        if cnt[sl].sum() > 0:
            out[sl] = _quad_cells(surf, center[sl], sigma_p[sl], wo[sl], V[sl], na[sl], nb[sl],
                                  cnt[sl], f0, ndf)
    return out * L


def _quad_cells(surf, center, sigma_p, wo, V, na, nb, cnt, f0, ndf):
    N = len(wo)
    off = np.concatenate([[0], np.cumsum(cnt)])
    P = int(off[-1])
    owner = np.repeat(np.arange(N), cnt)
    loc = np.arange(P) - off[owner]
    ia, ib = loc // nb[owner], loc % nb[owner]
    a = ((ia + 0.5) / na[owner])[:, None]
    b = ((ib + 0.5) / nb[owner])[:, None]
    v0, v1, v2, v3 = (V[owner, k] for k in range(4))
    Pt = (1 - a) * (1 - b) * v0 + a * (1 - b) * v1 + a * b * v2 + (1 - a) * b * v3
    dPa = (1 - b) * (v1 - v0) + b * (v2 - v3)
    dPb = (1 - a) * (v3 - v0) + a * (v2 - v1)
    cr = np.cross(dPa, dPb)
    r2 = np.sum(Pt * Pt, -1)
    wi = Pt / np.sqrt(r2)[:, None]
    # |cr| cos(theta_l) = |cr . wi| (cr is along the light's normal)
    dw = np.abs(np.sum(cr * wi, -1)) / (r2 * na[owner] * nb[owner])
    k, hh, ok = _smooth_factor(wo[owner], wi, f0)
    if ndf == "direct":
        D = pndf_multi(surf, center, sigma_p, hh[:, :2], off)
    else:
        from prefilter.glints.brdf import glint_ndf

        D = glint_ndf(surf, center[owner], sigma_p[owner], hh[:, :2])
    val = np.where(ok[:, None], np.broadcast_to(k, (P, 3)) * (D * dw)[:, None], 0.0)
    return np.stack([np.bincount(owner, val[:, ch], minlength=N) for ch in range(3)], -1)


def _box_blur_axis(T, r: float, h: float, axis: int) -> np.ndarray:
    """Mean over ``[x - r, x + r]`` of the piecewise-linear interpolant of node values ``T``
    along ``axis`` (zero beyond the grid), at the nodes."""
    T = np.moveaxis(T, axis, -1)
    R = T.shape[-1]
    # cumulative integral at the nodes (trapezoids), then exact within a cell
    C = np.concatenate([np.zeros(T.shape[:-1] + (1,)),
                        np.cumsum(0.5 * h * (T[..., 1:] + T[..., :-1]), -1)], -1)

    def cum(x):  # x in node units, (M,)
        x = np.clip(x, 0.0, R - 1)
        i = np.minimum(np.floor(x).astype(int), R - 2)
        t = x - i
        v0, v1 = T[..., i], T[..., i + 1]
        return C[..., i] + h * (v0 * t + 0.5 * (v1 - v0) * t * t)

    x = np.arange(R, dtype=np.float64)
    out = (cum(x + r / h) - cum(x - r / h)) / (2.0 * r)
    return np.moveaxis(out, -1, axis)


def environment_integral(surf, center, sigma_p, wo, mu, lam, p, f0=1.0, *, blur=None,
                         res: int = ENV_RES, chunk: int = 32) -> np.ndarray:
    """Specular ``int f cos L dw`` of an SG environment with the direct P-NDF, by quadrature.

    Glints paper eq. 1 with the environment of sec. 5.4: ``int D_p(s) K(s) ds``,
    ``K = F G L(w_i) (w_i.h) / (w_o_z h_z)``, ``K`` tabulated on ``res^2`` nodes over
    ``[-1, 1]^2`` per footprint and integrated against each P-NDF element
    (:func:`pndf_integral`).

    The table covers the square of ``s`` the P-NDF's elements reach (within 4 stds), at most
    ``[-1, 1]^2``, with node spacing ``2 / (res - 1)``.

    Parameters
    ----------
    wo : (N, 3) local view directions; mu (K, 3), lam (K,), p (N, K, 3) or (K, 3): the SG
        lobes in the local frame (:mod:`prefilter.glints.envlight`).
    blur : None, or (N,) half-widths ``r`` in ``s`` (0: none): the expectation of an estimator
        that replaces ``D(h)`` by its mean over ``h_xy +- r`` (``glints``' prefiltering), i.e.
        ``K`` box-filtered by ``+-r``.

    Returns
    -------
    (N, 3).
    """
    from prefilter.glints.envlight import as_lobes

    mu, lam, p = as_lobes(mu, lam, p)
    wo = as_float_array(wo, "wo", ndim_min=2, last_dim=3)
    N = len(wo)
    if p.ndim == 3 and p.shape[0] != N:
        raise PrefilterError(f"p: expected per-sample axes ({N}, K, 3), got {p.shape}")
    c = as_float_array(center, "center", ndim_min=2, last_dim=2)
    sp = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), (N,))
    r_blur = np.zeros(N) if blur is None else np.broadcast_to(as_float_array(blur, "blur"), (N,))
    if np.any(r_blur < 0):
        raise PrefilterError("blur: expected half-widths >= 0")
    f0 = np.atleast_1d(np.asarray(f0, dtype=np.float64))
    # the table spans the square the elements can reach (means shift by < 4 sqrt2 sigma_h |J|,
    # positional std < sigma_h |J|; 4 stds beyond): beyond it the integrand has no mass
    surf, s_el, J = _surface_arrays(surf)
    reach = np.abs(s_el).max(-1) + 10.0 * SIGMA_H * np.sqrt(np.sum(J * J, axis=(-2, -1)))
    # (+ the blur: a blurred node reads K up to r away)
    rmax = float(r_blur.max(initial=0.0))
    bound = min(1.0, float(reach.max()) + 4.0 * surf.intrinsic_roughness) + rmax
    hstep = 2.0 / (res - 1)
    n_nodes = int(np.ceil(2.0 * bound / hstep)) + 1
    lo = -0.5 * hstep * (n_nodes - 1)
    g = lo + hstep * np.arange(n_nodes)
    res = n_nodes
    SX, SY = np.meshgrid(g, g)  # row = s_y
    s2 = SX**2 + SY**2
    inside = s2 < 1.0
    hz = np.sqrt(np.maximum(1.0 - s2, 0.0))
    hgrid = np.stack([SX, SY, hz], -1).reshape(-1, 3)
    out = np.zeros((N, 3))
    for c0 in range(0, N, chunk):
        sl = slice(c0, min(N, c0 + chunk))
        w = wo[sl][:, None, :]
        dot = np.sum(w * hgrid[None], -1, keepdims=True)
        wi = 2.0 * dot * hgrid[None] - w
        k, _, ok = _smooth_factor(np.broadcast_to(w, wi.shape), wi, f0)
        ok &= inside.reshape(1, -1)
        if p.ndim == 2:
            Lw = np.exp(lam * (wi @ p.T - 1.0)) @ mu
        else:
            Lw = np.exp(lam * (np.einsum("nmc,nkc->nmk", wi, p[sl]) - 1.0)) @ mu
        jac = 4.0 * dot[..., 0] / np.where(ok, hgrid[None, :, 2], 1.0)
        T = np.where(ok[..., None], k * Lw * jac[..., None], 0.0).reshape(-1, res, res, 3)
        for i, r in enumerate(r_blur[sl]):
            if r > 0:
                T[i] = _box_blur_axis(_box_blur_axis(T[i], r, hstep, 1), r, hstep, 0)
        out[sl] = pndf_integral(surf, c[sl], sp[sl], T, lo, hstep)
    return out


# ------------------------------------------------------------------------------------ frames


def shade_converged(scene, g, *, matched: bool = False, ndf: str = "direct") -> np.ndarray:
    """Radiance ``(N, 3)`` of hit samples ``g`` with the direct P-NDF, without sampling noise.

    ``matched=False``: the expectation of ``glints-direct`` (point / directional lights as that
    method; quads by :func:`quad_integral`; environments by :func:`environment_integral`).
    ``matched=True``: the expectation of ``glints``' own estimators with the direct P-NDF in
    place of the compressed one: environments blurred over the lobes' epsilon-support where
    ``glints`` prefilters (footprints at or above the compressed map's ``sigma_min``); quads as
    for ``False`` (the range path's patch-centre factors and bounding-box means are not
    mirrored, so they stay in a comparison of ``glints`` against this).
    ``ndf="compressed"`` (quad, point and directional lights only): the same integrals with
    ``glints``' compressed NDF (its point queries, the render cache's map) instead of the direct
    P-NDF, i.e. ``glints`` without its light estimator's error.
    Footprints and shading frames are those of :func:`prefilter.glints.render.shade_glints`.
    """
    if ndf not in ("direct", "compressed"):
        raise PrefilterError(f"ndf: expected 'direct' or 'compressed', got {ndf!r}")
    from prefilter.glints.brdf import glint_brdf_cos
    from prefilter.glints.envlight import eps_support
    from prefilter.glints.render import ENV_EPS, baked_surface, environment_sgs, footprints
    from prefilter.ltc import clamped_cosine_integral
    from prefilter.render.shading import point_incoming, shading_frames
    from prefilter.sphere.sampling import to_local

    lights = scene.light_set()
    env = [lt for lt in scene.lights if lt.type == "environment"]
    t, b, n, wo = shading_frames(g)
    out = np.zeros((len(wo), 3))
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        if mat.normal_map is None:
            raise PrefilterError(f"objects[{int(k)}].material.normal_map: expected a normal map "
                                 "(the microstructure), got none")
        nm = mat.normal_map.load()
        surf = baked_surface(nm, direct=(ndf == "direct"))
        c, sp = footprints(g.select(m), surf.shape)
        base = np.asarray(mat.base_color, dtype=np.float64)
        f0 = np.asarray(mat.f0, dtype=np.float64)
        tm, bm, nmm = t[m], b[m], n[m]
        for w, e in point_incoming(lights, g.position[m]):
            wi = to_local(w, tm, bm, nmm)
            wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
            out[m] += (glint_brdf_cos(surf, c, sp, wo[m], wi, f0)
                       + base / np.pi * np.maximum(wi[:, 2], 0.0)[:, None]) * e
        for ql in lights.quads:
            corners = np.stack([to_local(v - g.position[m], tm, bm, nmm) for v in ql.vertices], 1)
            if np.any(base > 0):
                out[m] += base * ql.radiance * clamped_cosine_integral(corners)[:, None]
            out[m] += quad_integral(surf, c, sp, wo[m], corners, ql.radiance, f0,
                                    ndf="direct" if ndf == "direct" else "surface")
        if env and np.any(base > 0):
            raise PrefilterError(f"objects[{int(k)}].material.base_color: the converged "
                                 "environment reference is specular only; expected 0")
        if env and ndf != "direct":
            raise PrefilterError("ndf: the environment reference needs the direct P-NDF "
                                 "(element cubature); expected 'direct'")
        for light in env:
            mu, lam, p = environment_sgs(light)
            pl = np.stack([p @ tm.T, p @ bm.T, p @ nmm.T], -1).transpose(1, 0, 2)
            blur = None
            if matched:
                if np.ptp(lam) > 0:
                    raise PrefilterError("lam: the matched reference expects one sharpness for "
                                         "all lobes (one blur width)")
                big = sp >= baked_surface(nm).sigma_min
                blur = np.where(big, 0.5 * eps_support(mu, lam[:1], ENV_EPS)[0], 0.0)
            out[m] += environment_integral(surf, c, sp, wo[m], mu, lam, pl, f0, blur=blur)
    return out


def render_converged(scene, *, matched: bool = False, ndf: str = "direct",
                     chunk_samples: int = 1 << 14) -> np.ndarray:
    """Image ``(H, W, 3)`` float32 of :func:`shade_converged` at the pixel centres (the 1-spp
    samples of the ``glints`` methods)."""
    from prefilter.render.methods import RenderSettings
    from prefilter.render.driver import render_samples
    from prefilter.render.scene import Scene, load_scene

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    settings = RenderSettings(spp=1, seed=0, jitter=(0.0, 0.0), progress=False,
                              chunk_samples=int(chunk_samples), table=None)
    img = render_samples(scene, settings,
                         lambda g, u: shade_converged(scene, g, matched=matched, ndf=ndf),
                         random_dims=0, stratified=False, desc="glints-converged")
    return np.asarray(img, dtype=np.float32)
