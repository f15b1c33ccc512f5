"""Baking the anisotropic GGX LTC table (anisotropic-LTC paper, section 9, "Precomputations").

Per entry: SW fit from the identity (:func:`.fit.fit_sw`), an optional point-wise L1
polish kept only where it lowers the L1 distance (:func:`.fit.fit_pointwise`), alignment
(:func:`.align.align`, eq. 12), normalisation by the third column (section 7); then over the
whole grid the symmetry post-processing (:func:`.symmetry.enforce`, eq. 16) and the magnitude /
Fresnel quadrature.
Entries are fitted in chunks, each one tensor program; every finished chunk is checkpointed so a
killed bake resumes from the last finished chunk, and the table is written atomically.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from prefilter.fileio import Checkpoints, bake_lock
from prefilter.validation import as_positive_int
from prefilter.errors import PrefilterError
from prefilter.ltc.aniso.align import align
from prefilter.ltc.aniso.fit import (
    _torch,
    SWSettings,
    fit_pointwise,
    fit_sw,
    l1_distance,
    lobe_moments,
)
from prefilter.ltc.aniso.symmetry import enforce
from prefilter.sphere.polygon import clip_to_horizon
from prefilter.ltc.aniso.table import TABLE_VERSION, AnisoGGXTable, user_table_path


@dataclass(frozen=True)
class BakeSettings:
    """Everything that determines the baked bytes (stored in the table as JSON)."""

    res_theta: int = 8
    res_phi: int = 8
    res_alpha: int = 8
    res_ratio: int = 8
    #: Last view angle of the grid (degrees); larger angles use the last row.
    theta_max_deg: float = 86.0
    alpha_min: float = 0.05
    ratio_min: float = 0.05
    #: Entries per tensor program (and per checkpoint).
    chunk: int = 512
    moment_nodes: int = 64
    #: Monte Carlo samples of the per-entry L1 diagnostic (0: skip it).
    l1_samples: int = 4096
    sw: SWSettings = field(default_factory=SWSettings)
    #: Steps of the point-wise L1 polish started from each SW fit (0: none). Per entry, the
    #: polished matrix is kept only if its L1 distance (Monte Carlo, ``polish_check`` fresh
    #: samples) is lower than the SW fit's: the polish can never make an entry worse.
    polish_steps: int = 100
    polish_samples: int = 256
    polish_lr: float = 0.003
    polish_check: int = 2048
    #: Warm start: a baked table file whose fits before alignment (``diag_M_unaligned``) start
    #: every entry instead of the identity (empty: the identity). With ``sw.steps = 0`` the SW
    #: fit is skipped and only the polish runs from these fits; the polish is kept only where it
    #: lowers the L1 distance of the starting fit, so no entry gets worse than its start.
    init: str = ""
    #: With ``init``: also try the fits of the grid neighbours (one step along each axis) as
    #: starts, and polish from whichever has the lowest L1 distance at the entry (``polish_check``
    #: samples): an entry stuck in a poor local minimum restarts from a neighbour's basin.
    init_neighbours: bool = False

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Nodes: theta and phi uniform, alpha and ratio uniform in their square roots."""
        for name in ("res_theta", "res_phi", "res_alpha", "res_ratio"):
            as_positive_int(getattr(self, name), name, lo=2)
        if not (0 < self.theta_max_deg < 90 and 0 < self.alpha_min < 1 and
                0 < self.ratio_min < 1):
            raise PrefilterError(f"bake settings: expected 0 < theta_max_deg < 90 and alpha_min, "
                                 f"ratio_min in (0, 1), got {self.theta_max_deg}, "
                                 f"{self.alpha_min}, {self.ratio_min}")
        return (np.linspace(0.0, np.radians(self.theta_max_deg), self.res_theta),
                np.linspace(0.0, np.pi / 2, self.res_phi),
                np.linspace(np.sqrt(self.alpha_min), 1.0, self.res_alpha) ** 2,
                np.linspace(np.sqrt(self.ratio_min), 1.0, self.res_ratio) ** 2)

    def to_dict(self) -> dict:
        d = {"version": TABLE_VERSION, **asdict(self)}
        if self.init:  # the start determines the bytes: key checkpoints by its content
            d["init_sha256"] = _sha256(self.init)
        return d


def _sha256(path) -> str:
    import hashlib

    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError as exc:
        raise PrefilterError(f"init: expected a readable table file, got {str(path)!r} "
                             f"({exc.strerror})") from None


def initial_fits(settings: BakeSettings, entries) -> np.ndarray | None:
    """``(E, 3, 3)`` starting matrices of ``entries`` from ``settings.init`` (``None``: identity).

    The init table must have the same axes as ``settings`` and its ``diag_M_unaligned``.
    """
    if not settings.init:
        return None
    table = AnisoGGXTable.load(settings.init)
    M0 = table.diagnostics.get("M_unaligned")
    if M0 is None or any(len(a) != len(b) or not np.allclose(a, b)
                         for a, b in zip(table.axes, settings.axes())):
        raise PrefilterError(f"init: expected a baked table with the bake's axes and the "
                             f"diagnostic M_unaligned, got {settings.init!r}")
    i = entries["index"]
    own = np.asarray(M0[i[:, 0], i[:, 1], i[:, 2], i[:, 3]], np.float64)
    if not settings.init_neighbours:
        return own
    shape = np.array(M0.shape[:4])
    cands = [own]
    for axis in range(4):
        for step in (-1, 1):
            j = i.copy()
            j[:, axis] += step
            ok = np.all((j >= 0) & (j < shape), axis=1)
            j[~ok] = i[~ok]  # no neighbour across the border: the entry's own fit again
            cands.append(np.asarray(M0[j[:, 0], j[:, 1], j[:, 2], j[:, 3]], np.float64))
    return np.stack(cands, 1)  # (E, 9, 3, 3): own fit first


def best_start(M0, wo, alpha_x, alpha_y, n: int, seed: int) -> np.ndarray:
    """Per entry the candidate of ``M0 (B, C, 3, 3)`` with the lowest L1 distance -> (B, 3, 3).

    Every candidate is scored with the same random numbers (common samples), so the comparison
    is not decided by Monte Carlo noise between candidates.
    """
    M0 = np.asarray(M0, np.float64)
    M0 = M0 / np.linalg.norm(M0[..., :, 2], axis=-1)[..., None, None]
    d = np.stack([l1_distance(M0[:, c], wo, alpha_x, alpha_y, n, np.random.default_rng(seed))
                  for c in range(M0.shape[1])], 1)
    d[~np.isfinite(d)] = np.inf
    return M0[np.arange(len(M0)), np.argmin(d, axis=1)]


def grid_entries(settings: BakeSettings) -> dict[str, np.ndarray]:
    """The entries that are fitted: every grid node except ``theta = 0, phi > 0`` (same lobe).

    Returns ``index`` (E, 4) grid indices, ``wo`` (E, 3), ``alpha_x`` (E,), ``alpha_y`` (E,).
    """
    th, ph, al, ra = settings.axes()
    idx = np.stack(np.meshgrid(*(np.arange(len(a)) for a in (th, ph, al, ra)), indexing="ij"),
                   -1).reshape(-1, 4)
    idx = idx[(idx[:, 0] > 0) | (idx[:, 1] == 0)]
    t, p = th[idx[:, 0]], ph[idx[:, 1]]
    wo = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    a = al[idx[:, 2]]
    return {"index": idx, "wo": wo, "alpha_x": a, "alpha_y": a * ra[idx[:, 3]]}


def _fill(settings, entries, values):
    """Scatter per-entry ``values (E, ...)`` onto the grid, copying ``theta = 0`` across phi."""
    shape = tuple(len(a) for a in settings.axes())
    out = np.zeros(shape + values.shape[1:])
    i = entries["index"]
    out[i[:, 0], i[:, 1], i[:, 2], i[:, 3]] = values
    out[0, 1:] = out[0, :1]
    return out


def fit_entries(wo, alpha_x, alpha_y, settings: BakeSettings, chunk: int = 0, *,
                progress: Callable[[int], None] | None = None,
                M0=None) -> dict[str, np.ndarray]:
    """The bake's per-entry fit (before alignment): SW fit, then the L1 polish where it helps.

    ``wo (B, 3)``, ``alpha_x``, ``alpha_y (B,)``; ``chunk`` seeds the fit as chunk ``chunk`` of a
    bake (same bytes as the bake for the same entries); ``M0 (B, 3, 3)`` optional starting fits
    (default the identity; with ``settings.sw.steps = 0`` the SW fit is skipped), or
    ``(B, C, 3, 3)`` candidates of which the one with the lowest L1 distance starts. Returns
    ``M (B, 3, 3)`` (unit third column), ``loss (B,)`` (SW; NaN when skipped) and
    ``polished (B,)`` (bool: the polish was kept).
    """
    sw = replace(settings.sw, seed=settings.sw.seed * 100_003 + chunk)
    if M0 is not None and np.ndim(M0) == 4:  # candidates per entry (neighbour warm starts)
        M0 = best_start(M0, wo, alpha_x, alpha_y, settings.polish_check, sw.seed + 11)
    if sw.steps > 0:
        res = fit_sw(wo, alpha_x, alpha_y, sw, M0=M0, progress=progress)
    elif M0 is None:
        raise PrefilterError("steps: expected >= 1 without starting fits (init), got 0")
    else:
        M0 = np.asarray(M0, np.float64)
        res = {"M": M0 / np.linalg.norm(M0[..., :, 2], axis=-1)[..., None, None],
               "loss": np.full(len(wo), np.nan)}
    M, polished = res["M"], np.zeros(len(wo), bool)
    if settings.polish_steps:
        pol = fit_pointwise(wo, alpha_x, alpha_y, steps=settings.polish_steps,
                            n_samples=settings.polish_samples, lr=settings.polish_lr,
                            lr_final=settings.polish_lr / 30, power=1.0, seed=sw.seed,
                            M0=M, double=False)["M"]
        bad = ~np.all(np.isfinite(pol), axis=(1, 2))
        bad |= np.linalg.cond(np.where(bad[:, None, None], np.eye(3), pol)) > 1e7
        pol[bad] = M[bad]  # a diverged polish keeps the SW fit
        rng = np.random.default_rng(sw.seed + 7)
        d_sw = l1_distance(M, wo, alpha_x, alpha_y, settings.polish_check, rng)
        d_pol = l1_distance(pol, wo, alpha_x, alpha_y, settings.polish_check, rng)
        polished = d_pol < d_sw
        M = np.where(polished[:, None, None], pol, M)
    return {"M": M, "loss": res["loss"], "polished": polished}


def bake_table(out=None, settings: BakeSettings | None = None, *, progress: bool = True,
               on_chunk: Callable[[int], None] | None = None, wait: bool = False) -> Path:
    """Fit, align, post-process and write the table; returns the output path (default:
    :func:`~prefilter.ltc.aniso.table.user_table_path`, which ``AnisoGGXTable.load()`` then
    prefers to the shipped table).

    Resumable: chunk results live in ``<out>.parts/`` (keyed by the settings) until the table is
    written. The bake holds :func:`prefilter.fileio.bake_lock` on ``out``: while another bake of
    ``out`` runs it raises a PrefilterError naming that bake (``wait=True``: waits for it).
    ``on_chunk(i)`` is called after chunk ``i`` is checkpointed (tests interrupt bakes
    with it). Wall times are not stored: the same settings give the same bytes, resumed or not.
    """
    settings = settings or BakeSettings()
    if not isinstance(settings, BakeSettings):
        raise PrefilterError(f"settings: expected BakeSettings, got {type(settings).__name__}")
    # checked before any work (the fit would otherwise run, or fail deep inside)
    as_positive_int(settings.sw.steps, "steps", lo=0 if settings.init else 1)
    as_positive_int(settings.sw.seed, "seed", lo=0)
    settings.to_dict()  # a missing init file fails here, before any work
    _torch()  # the fit needs PyTorch: say so before any file (lock, checkpoints) is made
    out = Path(out) if out is not None else user_table_path()
    with bake_lock(out, wait=wait):
        return _bake_locked(out, settings, progress, on_chunk)


def _bake_locked(out: Path, settings: BakeSettings, progress: bool,
                 on_chunk: Callable[[int], None] | None) -> Path:
    entries = grid_entries(settings)
    E = len(entries["wo"])
    M_init = initial_fits(settings, entries)
    chunk = as_positive_int(settings.chunk, "chunk")
    n_chunks = -(-E // chunk)
    ck = Checkpoints(out, settings.to_dict())
    todo = [c for c in range(n_chunks) if not ck.done(c)]
    bar = None
    if progress:
        from tqdm import tqdm

        per = max(1, settings.sw.steps)  # without SW steps the bar counts chunks
        bar = tqdm(total=n_chunks * per, initial=(n_chunks - len(todo)) * per,
                   desc="ltc-aniso SW fit" if settings.sw.steps else "ltc-aniso polish",
                   unit="step" if settings.sw.steps else "chunk")
    try:
        for c in todo:
            sl = slice(c * chunk, min(E, (c + 1) * chunk))
            done = [0]

            def tick(step, done=done):
                if bar is not None:
                    bar.update(step - done[0])
                done[0] = step

            wo, ax, ay = entries["wo"][sl], entries["alpha_x"][sl], entries["alpha_y"][sl]
            res = fit_entries(wo, ax, ay, settings, c, progress=tick,
                              M0=None if M_init is None else M_init[sl])
            M, polished = res["M"], res["polished"]
            ck.save(c, M=M, loss=res["loss"], polished=polished)
            if bar is not None and not settings.sw.steps:
                bar.update(1)
            if on_chunk is not None:
                on_chunk(c)
    finally:
        if bar is not None:
            bar.close()
    parts = [ck.load(c) for c in range(n_chunks)]
    M_raw = np.concatenate([p["M"] for p in parts])
    loss = np.concatenate([p["loss"] for p in parts])
    table = finish_table(settings, entries, M_raw, loss, progress=progress)
    table.diagnostics["polished"] = _fill(settings, entries,
                                          np.concatenate([p["polished"] for p in parts]))
    table.save(out)
    ck.clear()
    return out


def finish_table(settings: BakeSettings, entries, M_raw, loss=None, *,
                 progress: bool = False) -> AnisoGGXTable:
    """Alignment, eq. 16 post-processing, moments and diagnostics for fitted ``M_raw (E, 3, 3)``."""
    axes = settings.axes()
    aligned = align(M_raw)["M"]
    aligned /= np.linalg.norm(aligned[..., :, 2], axis=-1)[..., None, None]
    grid_aligned = _fill(settings, entries, aligned)
    M = enforce(grid_aligned, axes[0], axes[1], axes[3])
    th, ph, al, ra = np.meshgrid(*axes, indexing="ij")
    wo = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    mom = lobe_moments(wo.reshape(-1, 3), al.reshape(-1), (al * ra).reshape(-1),
                       settings.moment_nodes)
    diagnostics = {"symmetry_change": np.abs(M - grid_aligned).max(axis=(-2, -1)),
                   "M_unaligned": _fill(settings, entries, M_raw)}
    if loss is not None:
        diagnostics["sw_loss"] = _fill(settings, entries, np.asarray(loss))
    if settings.l1_samples:
        l1 = np.zeros(len(wo.reshape(-1, 3)))
        rng = np.random.default_rng(settings.sw.seed + 1)
        Mf, wf, af, rf = M.reshape(-1, 3, 3), wo.reshape(-1, 3), al.reshape(-1), ra.reshape(-1)
        for s in range(0, len(l1), 256):
            e = slice(s, s + 256)
            l1[e] = l1_distance(Mf[e], wf[e], af[e], af[e] * rf[e], settings.l1_samples, rng)
        diagnostics["l1"] = l1.reshape(M.shape[:4])
    shape = M.shape[:4]
    return AnisoGGXTable(axes, M, mom["magnitude"].reshape(shape), mom["fresnel"].reshape(shape),
                         settings.to_dict(), diagnostics)


# --------------------------------------------------------------------------------------------
# Quad-light polish (beyond the paper; docs/ltc-aniso.md, "What limits the p90")
# --------------------------------------------------------------------------------------------


#: Conditioning bound of stored matrices, ``cond(M) <= COND_BOUND / alpha_min`` (docs/ltc-aniso.md,
#: "Conditioning"; the SW + L1 bake stays below 8.2).
COND_BOUND = 10.0


@dataclass(frozen=True)
class QuadPolishSettings:
    """Settings of :func:`quad_polish` (stored in the table's settings when applied)."""

    #: Training quads, drawn like the acceptance's and shared by every entry; with their
    #: mirror images in x, y and both (the symmetries of eq. 16), so ``4 n_quads`` in all.
    n_quads: int = 24
    #: Validation quads (as many, another seed): a refit is kept only if it lowers the
    #: objective on them (sharp lobes light few quads and overfit).
    lobe_samples: int = 2048
    light_samples: int = 512
    #: Objective of :func:`~prefilter.ltc.aniso.quadfit.fit_quad_ltc` ("l1" or "l2").
    loss: str = "l1"
    #: Seed of the quads and references (never 0, the acceptance's seed).
    seed: int = 1
    processes: int = 1


def _mirrored(quads):
    """``quads (K, 4, 3)`` and their images under x -> -x, y -> -y and both ``(4K, 4, 3)``;
    vertex order reversed for the single mirrors so that they stay front-facing."""
    out = [quads]
    for s, rev in (((-1, 1, 1), True), ((1, -1, 1), True), ((-1, -1, 1), False)):
        q = quads * np.array(s, float)
        out.append(q[:, ::-1] if rev else q)
    return np.concatenate(out)


def _objective(err, loss):
    return np.mean(err**2) if loss == "l2" else np.mean(err)


def _polish_job(args):
    from prefilter.ltc.aniso.quadfit import fit_quad_ltc, quad_references
    from prefilter.sphere.polygon import polygon_integral

    wo, ax, ay, mag, M0, quads, valid, idx, qs = args
    out = np.array(M0, copy=True)
    kept = np.zeros(len(wo), bool)
    clipped = clip_to_horizon(valid)
    for j in range(len(wo)):
        refs = [quad_references(wo[j], ax[j], ay[j], q, qs.lobe_samples, qs.light_samples,
                                np.random.default_rng([qs.seed, k, int(idx[j])]))
                for k, q in enumerate((quads, valid))]
        if min(np.count_nonzero(r >= 1e-3) for r in refs) < 8:
            continue  # too few lit quads to fit or to judge: keep the density fit
        M = fit_quad_ltc(quads, refs[0], mag[j], M0[j], loss=qs.loss, fit_scale=False)["M"]
        if np.linalg.cond(M) > COND_BOUND / min(ax[j], ay[j]):
            continue  # degenerate refit (the quads only constrain part of the lobe)
        lit = refs[1] >= 1e-3

        def err(m):
            return np.abs(mag[j] * polygon_integral(m, clipped[lit]) / refs[1][lit] - 1.0)

        if _objective(err(M), qs.loss) < _objective(err(M0[j]), qs.loss):
            out[j], kept[j] = M, True
    return out, kept


def quad_polish(table: AnisoGGXTable, qs: QuadPolishSettings = QuadPolishSettings(), *,
                progress: bool = True) -> AnisoGGXTable:
    """Refit every entry of ``table`` on the acceptance metric, then re-align and apply eq. 16.

    Per entry, :func:`~prefilter.ltc.aniso.quadfit.fit_quad_ltc` (magnitude fixed) started from
    the stored matrix, on quads shared by all entries (``qs.n_quads`` and their mirror images)
    with MC references (:func:`~prefilter.ltc.aniso.quadfit.quad_references`); the refit is kept
    only where it is better on as many validation quads. Magnitude and Fresnel are unchanged;
    ``diagnostics["quad_polished"]`` marks the refitted entries.
    """
    from prefilter.ltc.aniso.quadfit import QUAD_LOSSES, acceptance_quads

    if qs.loss not in QUAD_LOSSES or qs.seed == 0:
        raise PrefilterError(f"quad polish: expected loss in {sorted(QUAD_LOSSES)} and a seed "
                             f"other than 0 (the acceptance's), got {qs.loss!r}, {qs.seed}")
    settings = BakeSettings(**{k: v for k, v in table.settings.items()
                               if k in BakeSettings.__dataclass_fields__ and k != "sw"})
    th, ph, al, ra = table.axes
    entries = grid_entries(settings)
    i = entries["index"]
    wo = np.stack([np.sin(th[i[:, 0]]) * np.cos(ph[i[:, 1]]),
                   np.sin(th[i[:, 0]]) * np.sin(ph[i[:, 1]]), np.cos(th[i[:, 0]])], -1)
    ax, ay = al[i[:, 2]], al[i[:, 2]] * ra[i[:, 3]]
    M0 = table.M[i[:, 0], i[:, 1], i[:, 2], i[:, 3]]
    mag = table.magnitude[i[:, 0], i[:, 1], i[:, 2], i[:, 3]]
    quads = _mirrored(acceptance_quads(qs.n_quads, np.random.default_rng([qs.seed, 0])))
    valid = _mirrored(acceptance_quads(qs.n_quads, np.random.default_rng([qs.seed, 1])))
    jobs = [(wo[s:s + 32], ax[s:s + 32], ay[s:s + 32], mag[s:s + 32], M0[s:s + 32], quads,
             valid, np.arange(s, min(s + 32, len(wo))), qs) for s in range(0, len(wo), 32)]
    if qs.processes > 1:
        import multiprocessing

        pool = multiprocessing.get_context("fork").Pool(qs.processes)
        results = pool.imap(_polish_job, jobs)
    else:
        pool, results = None, map(_polish_job, jobs)
    if progress:
        from tqdm import tqdm

        results = tqdm(results, total=len(jobs), desc="ltc-aniso quad polish", unit="chunk")
    try:
        parts = list(results)
    finally:
        if pool is not None:
            pool.close()
    M = np.concatenate([p[0] for p in parts])
    kept = np.concatenate([p[1] for p in parts])
    aligned = align(M)["M"]
    aligned /= np.linalg.norm(aligned[..., :, 2], axis=-1)[..., None, None]
    M_new = enforce(_fill(settings, entries, aligned), th, ph, ra)
    # eq. 16 averages and zeroes entries; where that leaves a bad matrix keep the table's
    amin = (al[:, None] * ra[None, :])[None, None]
    bad = (np.linalg.det(M_new) <= 0) | (np.linalg.cond(M_new) > COND_BOUND / amin)
    M_new[bad] = table.M[bad]
    diagnostics = dict(table.diagnostics)
    diagnostics["quad_polished"] = _fill(settings, entries, kept) * ~bad
    diagnostics["quad_polish_change"] = np.abs(M_new - table.M).max(axis=(-2, -1))
    return AnisoGGXTable(table.axes, M_new, table.magnitude, table.fresnel,
                         {**table.settings, "quad_polish": asdict(qs)}, diagnostics)


def repolish(table: AnisoGGXTable, power: float, *, seed: int = 0) -> AnisoGGXTable:
    """The bake's point-wise polish rerun with exponent ``power`` on a table's stored fits.

    Starts every entry from ``diagnostics["M_unaligned"]`` (the bake's fits before alignment),
    runs :func:`~prefilter.ltc.aniso.fit.fit_pointwise` with the table's polish settings and
    ``|p - q|^power``, keeps each result unless it diverged, then aligns and applies eq. 16;
    magnitude and Fresnel are unchanged (docs/ltc-aniso.md, "What limits the p90").
    """
    if "M_unaligned" not in table.diagnostics:
        raise PrefilterError("table: expected the diagnostic array M_unaligned (a baked table)")
    settings = BakeSettings(**{k: v for k, v in table.settings.items()
                               if k in BakeSettings.__dataclass_fields__ and k != "sw"})
    entries = grid_entries(settings)
    i = entries["index"]
    M0 = table.diagnostics["M_unaligned"][i[:, 0], i[:, 1], i[:, 2], i[:, 3]]
    out = np.empty_like(M0)
    for c in range(0, len(M0), settings.chunk):
        sl = slice(c, c + settings.chunk)
        pol = fit_pointwise(entries["wo"][sl], entries["alpha_x"][sl], entries["alpha_y"][sl],
                            steps=settings.polish_steps, n_samples=settings.polish_samples,
                            lr=settings.polish_lr, lr_final=settings.polish_lr / 30,
                            power=power, seed=seed * 100_003 + c // settings.chunk, M0=M0[sl],
                            double=False)["M"]
        bad = ~np.all(np.isfinite(pol), axis=(1, 2))
        bad |= np.linalg.cond(np.where(bad[:, None, None], np.eye(3), pol)) > 1e7
        pol[bad] = M0[sl][bad]  # a diverged polish keeps the stored fit
        out[sl] = pol
    aligned = align(out)["M"]
    aligned /= np.linalg.norm(aligned[..., :, 2], axis=-1)[..., None, None]
    M = enforce(_fill(settings, entries, aligned), *table.axes[:2], table.axis_ratio)
    return AnisoGGXTable(table.axes, M, table.magnitude, table.fresnel,
                         {**table.settings, "repolish_power": power},
                         {"M_unaligned": _fill(settings, entries, out)})
