"""Sliced-Wasserstein fitting of LTCs to anisotropic GGX lobes, batched over table entries.

Kt, Dupuy, Heitz (anisotropic-ggx-ltc), section 4 and Algorithm 3 (``equations.md`` 3): for each
entry, exact samples ``t_j`` of the normalised cosine-weighted GGX lobe (Algorithm 1: visible
normals + rejection with ``G2 / G1``) and differentiable LTC samples ``l_j = M c_j / |M c_j|``
(``c_j`` cosine samples, Algorithm 2) are projected on random unit directions ``d_k``; the loss
is the mean of ``|sort(l.d_k)_j - sort(t.d_k)_j|``. Gradients w.r.t. the nine entries of ``M``
come from PyTorch autograd (the ``prefilter[fit]`` extra; imported only inside these functions).

One tensor program fits a whole chunk of entries ``(B, 3, 3)``: entries never interact (the
loss is a sum of per-entry terms and Adam's update is per parameter), so a chunk is ``B``
independent fits run in lock-step. Differences from the paper, all for speed on a CPU:

- Adam with a cosine-decayed step (the paper: SGD, 10 000 steps); ``M`` is renormalised to a
  unit third column after every step (the loss is scale invariant, so this only fixes the
  step size's meaning).
- The target is a fixed pool of exact lobe samples per entry; every step uses a random subset.
- The projection directions are redrawn every ``redraw`` steps rather than every step, so the
  sorted target projections are reused in between; the LTC side is sorted every step.

:func:`fit_pointwise` is the point-wise density loss of Heitz et al. 2016 with the same optimiser:
from the identity it shows (tests) why the paper abandoned it for sharp lobes; from an SW fit,
with the bounded L1 loss, it is the bake's optional polish (``docs/ltc-aniso.md``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from prefilter.validation import as_float_array, as_roughness, as_rng, as_upper_directions
from prefilter.errors import PrefilterError
from prefilter.microfacet import GGX, reflect


@dataclass(frozen=True)
class SWSettings:
    """Settings of :func:`fit_sw` (they determine the fitted bytes; stored in tables)."""

    steps: int = 300
    #: LTC and target samples per step and entry (sorted along this axis).
    n_samples: int = 128
    #: Exact target samples per entry drawn once; each step uses ``n_samples`` of them.
    pool: int = 2048
    #: Random projection directions (paper: 64 per step).
    n_dirs: int = 16
    #: Steps between redraws of the projection directions.
    redraw: int = 4
    lr: float = 0.05
    lr_final: float = 5e-4
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def _torch():
    try:
        import torch
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise PrefilterError(
            "fitting the anisotropic LTC table needs PyTorch: pip install 'prefilter[fit]'"
        ) from exc
    # one thread: on a shared 2-core machine a second thread spends its time spin-waiting
    torch.set_num_threads(1)
    return torch


def _check_entries(wo, alpha_x, alpha_y):
    wo = as_upper_directions(wo, "wo")
    if wo.ndim != 2:
        raise PrefilterError(f"wo: expected shape (B, 3), got {wo.shape}")
    ax = np.broadcast_to(as_roughness(alpha_x, "alpha_x"), wo.shape[:1]).astype(np.float64)
    ay = np.broadcast_to(as_roughness(alpha_y, "alpha_y"), wo.shape[:1]).astype(np.float64)
    return wo, ax, ay


def lobe_samples(wo, alpha_x, alpha_y, n: int, rng) -> np.ndarray:
    """``n`` exact samples per entry ``(B, n, 3)`` of the normalised cosine-weighted GGX lobes.

    Anisotropic-LTC paper, Algorithm 1 (visible normals, accept with ``G2 / G1``), vectorised
    over entries: each round draws candidates for all entries and keeps the accepted ones in
    order until every entry has ``n``.

    Parameters
    ----------
    wo : (B, 3) views above the surface. alpha_x, alpha_y : (B,) or scalars.
    """
    wo, ax, ay = _check_entries(wo, alpha_x, alpha_y)
    rng = as_rng(rng)
    B = len(wo)
    lam_o = GGX(ax, ay).smith_lambda(wo)
    out = np.zeros((B, n, 3))
    count = np.zeros(B, np.intp)
    rows = np.arange(B)[:, None]
    k = max(64, int(1.5 * n))
    while np.any(count < n):
        todo = np.flatnonzero(count < n)
        sub = GGX(ax[todo, None], ay[todo, None])
        m = sub.sample_vndf(np.broadcast_to(wo[todo, None, :], (len(todo), k, 3)),
                            rng.random((len(todo), k, 2)))
        wi = reflect(wo[todo, None, :], m)
        up = wi[..., 2] > 0.0
        lam_i = sub.smith_lambda(wi)
        # G2 / G1 = (1 + Lambda_o) / (1 + Lambda_o + Lambda_i)
        ratio = (1.0 + lam_o[todo, None]) / (1.0 + lam_o[todo, None] + lam_i)
        acc = up & (rng.random((len(todo), k)) < ratio)
        pos = count[todo, None] + np.cumsum(acc, axis=1) - 1
        keep = acc & (pos < n)
        r = np.broadcast_to(rows[todo], keep.shape)
        out[r[keep], pos[keep]] = wi[keep]
        count[todo] = np.minimum(n, count[todo] + acc.sum(1))
    return out


def lobe_moments(wo, alpha_x, alpha_y, nodes: int = 64) -> dict[str, np.ndarray]:
    """Magnitude ``n`` and Fresnel scalar ``f5`` of anisotropic GGX lobes (Fresnel = 1 BRDF).

    Heitz et al. 2016 / Hill and Heitz 2016 (``equations.md`` 2): ``n = integral f cos dwi``,
    ``f5 = integral f cos (1 - wi.h)^5 dwi``; Gauss-Legendre quadrature in the unit square of
    visible-normal sampling, where the integrand is ``G2 / G1`` (times ``(1 - wo.m)^5``).

    Parameters
    ----------
    wo : (..., 3); alpha_x, alpha_y : (...) broadcasting with ``wo[..., 0]``.

    Returns
    -------
    dict with ``magnitude`` and ``fresnel``, both ``(...)``.
    """
    wo = as_upper_directions(wo, "wo")
    ax = as_roughness(alpha_x, "alpha_x")
    ay = as_roughness(alpha_y, "alpha_y")
    x, w = np.polynomial.legendre.leggauss(nodes)
    x = (x + 1.0) / 2.0
    u = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    wgt = (w[:, None] * w[None, :]).reshape(-1) / 4.0
    model = GGX(ax[..., None], ay[..., None])
    wo_b = wo[..., None, :]
    m = model.sample_vndf(wo_b, u)
    wi = reflect(wo_b, m)
    lam_o = GGX(ax, ay).smith_lambda(wo)[..., None]
    lam_i = model.smith_lambda(wi)
    ratio = np.where(wi[..., 2] > 0.0, (1.0 + lam_o) / (1.0 + lam_o + lam_i), 0.0) * wgt
    f5 = np.sum(ratio * (1.0 - np.clip(np.sum(wo_b * m, -1), 0.0, 1.0)) ** 5, -1)
    return {"magnitude": ratio.sum(-1), "fresnel": f5}


def _cosine(torch, u):
    r = torch.sqrt(u[..., 0])
    phi = 2.0 * np.pi * u[..., 1]
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), torch.sqrt(1.0 - u[..., 0])], -1)


def _directions(torch, gen, B, K):
    d = torch.randn(B, K, 3, generator=gen, dtype=torch.float32)
    return d / d.norm(dim=-1, keepdim=True)


def _normalise(M):
    return M / M[..., :, 2].norm(dim=-1)[..., None, None]


def fit_sw(wo, alpha_x, alpha_y, settings: SWSettings = SWSettings(), *, M0=None,
           target=None, progress=None) -> dict[str, np.ndarray]:
    """Sliced-Wasserstein LTC fits of a chunk of GGX lobes (anisotropic-LTC paper, Algorithm 3).

    Parameters
    ----------
    wo : (B, 3) views in the tangent frame (x = tangent), above the surface.
    alpha_x, alpha_y : (B,) or scalars, GGX roughness.
    settings : :class:`SWSettings`.
    M0 : optional (B, 3, 3) initial matrices; default the identity (a diffuse lobe).
    target : optional (B, P, 3) exact lobe samples (default: ``settings.pool`` drawn from
        ``settings.seed`` with :func:`lobe_samples`).
    progress : optional callable ``progress(steps_done)``.

    Returns
    -------
    dict with ``M`` (B, 3, 3) (unit third column, not yet aligned) and ``loss`` (B,) the final
    SW loss (mean over the last 10 % of the steps).
    """
    torch = _torch()
    wo, ax, ay = _check_entries(wo, alpha_x, alpha_y)
    s = settings
    B = len(wo)
    rng = np.random.default_rng(s.seed)
    if target is None:
        target = lobe_samples(wo, ax, ay, s.pool, rng)
    T = torch.as_tensor(np.asarray(target), dtype=torch.float32)
    P = T.shape[1]
    gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
    M = torch.eye(3).repeat(B, 1, 1) if M0 is None else torch.as_tensor(
        as_float_array(M0, "M0"), dtype=torch.float32).clone()
    M = _normalise(M).requires_grad_(True)
    opt = torch.optim.Adam([M], lr=s.lr)
    N, K = s.n_samples, s.n_dirs
    tail = max(1, s.steps // 10)
    loss_tail = torch.zeros(B)
    history = np.zeros((s.steps, B), np.float32)
    for step in range(s.steps):
        lr = s.lr_final + 0.5 * (s.lr - s.lr_final) * (1 + np.cos(np.pi * step / s.steps))
        for g in opt.param_groups:
            g["lr"] = lr
        if step % s.redraw == 0:
            d = _directions(torch, gen, B, K)
            idx = torch.randint(P, (B, N), generator=gen)
            t = torch.gather(T, 1, idx[..., None].expand(B, N, 3))
            pt = torch.sort(torch.einsum("bni,bki->bkn", t, d), dim=-1).values
        c = _cosine(torch, torch.rand(B, N, 2, generator=gen))
        lw = torch.einsum("bij,bnj->bni", M, c)
        lw = lw / lw.norm(dim=-1, keepdim=True)
        pl = torch.sort(torch.einsum("bni,bki->bkn", lw, d), dim=-1).values
        per_entry = (pl - pt).abs().mean(dim=(1, 2))
        opt.zero_grad()
        per_entry.sum().backward()
        opt.step()
        with torch.no_grad():
            M.copy_(_normalise(M))
            history[step] = per_entry.detach().numpy()
            if step >= s.steps - tail:
                loss_tail += per_entry.detach() / tail
        if progress is not None:
            progress(step + 1)
    return {"M": M.detach().double().numpy(), "loss": loss_tail.double().numpy(),
            "history": history}


def _ggx_torch(torch, wo, ax, ay, wi):
    """Cosine-weighted GGX ``D(h) G2 / (4 wo_z)`` in torch (``equations.md`` 1), batched."""

    def lam(w):
        a2 = ((ax * w[..., 0]) ** 2 + (ay * w[..., 1]) ** 2) / w[..., 2].clamp_min(1e-12) ** 2
        return a2 / (1 + torch.sqrt(1 + a2)) / 2

    h = wo + wi
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    t = (h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2 + h[..., 2] ** 2
    D = 1.0 / (np.pi * ax * ay * t * t)
    g2 = 1.0 / (1 + lam(wo) + lam(wi))
    ok = (wi[..., 2] > 0) & (h[..., 2] > 0)
    return torch.where(ok, D * g2 / (4 * wo[..., 2]), torch.zeros_like(D))


def fit_pointwise(wo, alpha_x, alpha_y, *, steps: int = 600, n_samples: int = 1024,
                  lr: float = 0.05, lr_final: float = 5e-4, power: float = 2.0, seed: int = 0,
                  M0=None, double: bool = True) -> dict[str, np.ndarray]:
    """Point-wise fit (Heitz et al. 2016's density error) with the optimiser of :func:`fit_sw`.

    Minimises ``integral |p - q|^power`` between the normalised lobe ``p`` and the LTC ``q``,
    estimated each step with fresh samples of ``(p + q) / 2`` (half exact lobe samples, half LTC
    samples; the estimate is unbiased and differentiable through ``q``'s evaluations and the LTC
    samples). Same initialisation (identity), Adam and step schedule as :func:`fit_sw`, so the
    comparison isolates the loss. Returns ``{"M": (B, 3, 3)}``.

    From a good start (``M0`` = an SW fit) and with ``power = 1`` (the L1 distance, bounded) it
    is also the bake's optional *polish* step, which lowers the density error of SW fits.
    """
    torch = _torch()
    wo, ax, ay = _check_entries(wo, alpha_x, alpha_y)
    B = len(wo)
    rng = np.random.default_rng(seed)
    mag = lobe_moments(wo, ax, ay)["magnitude"]
    dt = torch.float64 if double else torch.float32
    pool = torch.as_tensor(lobe_samples(wo, ax, ay, 16 * n_samples, rng), dtype=dt)
    gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
    wo_t = torch.as_tensor(wo, dtype=dt)[:, None, :]
    ax_t = torch.as_tensor(ax, dtype=dt)[:, None]
    ay_t = torch.as_tensor(ay, dtype=dt)[:, None]
    mag_t = torch.as_tensor(mag, dtype=dt)[:, None]
    M = torch.eye(3, dtype=dt).repeat(B, 1, 1) if M0 is None else torch.as_tensor(
        as_float_array(M0, "M0"), dtype=dt).clone()
    M = _normalise(M).requires_grad_(True)
    opt = torch.optim.Adam([M], lr=lr)
    half = n_samples // 2
    for step in range(steps):
        for g in opt.param_groups:
            g["lr"] = lr_final + 0.5 * (lr - lr_final) * (1 + np.cos(np.pi * step / steps))
        idx = torch.randint(pool.shape[1], (B, half), generator=gen)
        t = torch.gather(pool, 1, idx[..., None].expand(B, half, 3))
        c = _cosine(torch, torch.rand(B, half, 2, generator=gen, dtype=dt))
        lw = torch.einsum("bij,bnj->bni", M, c)
        lw = lw / lw.norm(dim=-1, keepdim=True)
        w = torch.cat([lw, t], dim=1)
        Minv = torch.linalg.inv(M)
        lo = torch.einsum("bij,bnj->bni", Minv, w)
        length = lo.norm(dim=-1)
        q = (lo[..., 2] / length).clamp_min(0) / np.pi * torch.linalg.det(Minv).abs()[:, None] \
            / length**3
        p = _ggx_torch(torch, wo_t, ax_t, ay_t, w) / mag_t
        # the sampling density (p + q) / 2 is held fixed: only the integrand is differentiated
        pdf = (0.5 * (p + q)).detach().clamp_min(1e-12)
        loss = ((p - q).abs() ** power / pdf).mean(dim=1)
        opt.zero_grad()
        loss.sum().backward()
        opt.step()
        with torch.no_grad():
            M.copy_(_normalise(M))
    return {"M": M.detach().double().numpy()}


def l1_distance(M, wo, alpha_x, alpha_y, n: int, rng) -> np.ndarray:
    """``integral |p - q| dw`` in ``[0, 2]`` between normalised GGX lobes and LTCs, per entry.

    Independent of the fit: Monte Carlo with ``n`` samples of the mixture ``(p + q) / 2`` (half
    exact lobe samples, half LTC samples) and the closed-form densities ``GGX.eval / albedo`` and
    ``LTC.eval``. ``M (B, 3, 3)``, ``wo (B, 3)``; returns ``(B,)``.
    """
    from prefilter.ltc.ltc import LTC

    wo, ax, ay = _check_entries(wo, alpha_x, alpha_y)
    rng = as_rng(rng)
    B, h = len(wo), n // 2
    ltc = LTC(np.asarray(M, np.float64)[:, None])
    w = np.concatenate([lobe_samples(wo, ax, ay, h, rng), ltc.sample(rng.random((B, h, 2)))], 1)
    model = GGX(ax[:, None], ay[:, None])
    mag = lobe_moments(wo, ax, ay)["magnitude"][:, None]
    p = model.eval(wo[:, None, :], w) / mag
    q = ltc.eval(w)
    return np.mean(np.abs(p - q) / (0.5 * (p + q)), axis=1)
