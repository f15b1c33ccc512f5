"""Blocks, groups and non-negative CP decomposition of NDF images (glints paper, sec. 4.2, eq. 5).

NDF images ``(R, R)`` are cut into ``B x B`` blocks (``R / B`` per side); blocks whose values are
all below ``blank_tol`` times their image's maximum are dropped ("blank"). A group's blocks are
stacked into a tensor ``T (B, B, K)`` and factorised as ``T[i, j, k] ~ sum_r a_r[i] b_r[j] c_r[k]``
with non-negative factors (sampling in part 2 needs non-negative values, so no clamp is needed).

We normalise ``sum_i a_r[i] = sum_j b_r[j] = 1`` (the weight ``lambda_r`` is folded into
``c_r``), so the mean of block ``k`` is ``sum_r c_r[k] / B^2`` and the 1D prefix sums of
``a_r`` and ``b_r`` run from 0 to 1 (paper, sec. 4.4: range means from 1D summed-area tables).

Solvers: ``"hals"`` is hierarchical alternating least squares (Cichocki & Phan 2009) written for
this tensor shape (one BLAS matrix product per MTTKRP), about 10-50x faster than tensorly's generic
``non_negative_parafac_hals`` on these sizes; ``"tensorly"`` calls the latter. Both minimise the
same objective; the tests check that ``"hals"`` reaches tensorly's error.
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os

import numba
import numpy as np

from prefilter.jit import FASTMATH
from prefilter.validation import as_positive_int
from prefilter.errors import PrefilterError

#: Version of the fit's results: bumped whenever a change to :func:`nn_cp` (or what the bake does
#: with it) changes the factors it returns for the same inputs. The render and Wang-tile caches and
#: the bake's checkpoints key on it, so files fitted by an older version are never reused (5: the
#: bake's pass 1 runs half of the iterations, the final fit continues every group,
#: :func:`prefilter.glints.bake.pass1_iters`; 4: :data:`HALS_SWEEPS` column sweeps per product with
#: the tensor; 3: the HALS column sweep reads G by rows, a different rounding; 2: the relative stop
#: test ``prev - err < tol err``; 1: an absolute one).
FIT_VERSION = 5
#: HALS column sweeps per mode and iteration, all with the same products ``M = X W`` and
#: ``G = W^T W`` (the "accelerated HALS" of Gillis and Glineur 2012, Neural Computation 24(4)):
#: the products with the tensor are the cost of an iteration, a sweep costs ``rows R^2``. On a
#: level-0 cell of the render's 256^2 gaussian map at rank 24 (158 groups) 20 iterations with 6
#: sweeps reach 2.91 % relative error in 0.72 s, 50 iterations with one sweep 3.16 % in 1.55 s
#: (``benchmarks/bench_glints_hals.py``).
HALS_SWEEPS = 6


def _openblas():
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), "..", "numpy.libs", "*openblas*"))
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    return get, put
    return None


@contextlib.contextmanager
def single_threaded_blas():
    """Run OpenBLAS single-threaded inside the block (no-op if its controls are not found).

    The batched products here are small; on a shared, oversubscribed machine OpenBLAS's worker
    threads spin-wait and made the CP ~10x slower than one thread. The bake parallelises over
    spatial cells instead.
    """
    fns = _openblas()
    if fns is None:
        yield
        return
    get, put = fns
    old = get()
    put(1)
    try:
        yield
    finally:
        put(old)


def cut_blocks(images: np.ndarray, block: int) -> np.ndarray:
    """Blocks ``(..., nb, nb, B, B)`` of images ``(..., R, R)``: ``[bi, bj]`` covers rows
    ``bi B .. bi B + B - 1`` and columns ``bj B ..``."""
    R = images.shape[-1]
    if images.shape[-2] != R or R % block:
        raise PrefilterError(f"block: expected a divisor of the NDF resolution {R}, got {block}")
    nb = R // block
    shp = images.shape[:-2] + (nb, block, nb, block)
    return np.swapaxes(images.reshape(shp), -3, -2)


def blank_mask(blocks: np.ndarray, image_max: np.ndarray, blank_tol: float) -> np.ndarray:
    """``(..., nb, nb)`` True where a block is blank: every value <= ``blank_tol * image_max``."""
    return blocks.max(axis=(-1, -2)) <= blank_tol * image_max[..., None, None]


def _khatri_rao(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Column-wise Kronecker product ``(I J, R)`` with row index ``i * J + j``."""
    return (x[:, None, :] * y[None, :, :]).reshape(-1, x.shape[1])


def _hals_update(F: np.ndarray, M: np.ndarray, G: np.ndarray, eps: float) -> None:
    """:data:`HALS_SWEEPS` HALS sweeps over the columns of ``F`` for ``min |X - F W^T|`` with
    ``M = X W``, ``G = W^T W``, keeping ``F >= eps`` (in place). The tiny floor ``eps`` keeps a
    component from dying for good (an all-zero column would zero its Gram entry and never be
    updated again).
    ``F`` C-contiguous; the sweeps are :func:`_hals_columns`' for a batch of one."""
    _hals_columns(F[None], np.ascontiguousarray(M)[None], np.ascontiguousarray(G)[None],
                  np.array([eps]), np.zeros((1, F.shape[0]), bool), 1e-300, HALS_SWEEPS)


def nn_cp(tensor: np.ndarray, rank: int, *, n_iter_max: int = 200, tol: float = 1e-5,
          seed: int = 0, method: str = "hals") -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Non-negative rank-``rank`` CP decomposition of a ``(I, J, K)`` tensor (paper, eq. 5).

    Parameters
    ----------
    tensor : (I, J, K) non-negative array.
    rank : number of rank-one terms ``R``.
    n_iter_max : iteration cap (the paper uses ALS with at most 500 iterations).
    tol : stop when the relative error improves by less than ``tol`` times itself between
        iterations (relative: an absolute test stops the bake's fits, whose errors sit near 1e-3,
        after a few iterations with leaked values over empty NDF regions; ``method="tensorly"``
        passes ``tol`` on with tensorly's meaning).
    seed : seed of the random non-negative initialisation.
    method : ``"hals"`` (this module) or ``"tensorly"`` (``non_negative_parafac_hals``).

    Returns
    -------
    a : (I, R), b : (J, R) with columns summing to 1 (or zero columns), c : (K, R) with the weights
    folded in, and the relative Frobenius error ``|T - T_hat| / |T|``.
    """
    T = np.asarray(tensor, dtype=np.float64)
    if T.ndim != 3:
        raise PrefilterError(f"tensor: expected shape (I, J, K), got {T.shape}")
    if np.any(T < 0) or not np.all(np.isfinite(T)):
        raise PrefilterError("tensor: expected finite non-negative values")
    R = as_positive_int(rank, "rank")
    I, J, K = T.shape
    norm = np.linalg.norm(T)
    if norm == 0.0:
        return np.zeros((I, R)), np.zeros((J, R)), np.zeros((K, R)), 0.0
    if method == "tensorly":
        import tensorly as tl
        from tensorly.decomposition import non_negative_parafac_hals

        cp = non_negative_parafac_hals(tl.tensor(T), R, n_iter_max=n_iter_max, tol=tol,
                                       init="random", random_state=seed)
        a, b, c = (np.asarray(f, dtype=np.float64) for f in cp.factors)
        c = c * np.asarray(cp.weights, dtype=np.float64)[None, :]
    elif method == "hals":
        a, b, c = _hals(T, R, n_iter_max, tol, seed)
    else:
        raise PrefilterError(f"method: expected 'hals' or 'tensorly', got {method!r}")
    return _normalised(a, b, c, T)


def _hals(T, R, n_iter_max, tol, seed):
    I, J, K = T.shape
    rng = np.random.default_rng(seed)
    X1 = T.reshape(I, J * K)  # rows i, columns j * K + k
    X2 = np.ascontiguousarray(T.transpose(1, 0, 2)).reshape(J, I * K)  # columns i * K + k
    X3 = T.reshape(I * J, K).T  # (K, I J), columns i * J + j
    scale = (np.linalg.norm(T) / np.sqrt(I * J * K)) ** (1.0 / 3.0)
    a = rng.random((I, R)) * scale
    b = rng.random((J, R)) * scale
    c = rng.random((K, R)) * scale
    normT2 = float(np.sum(T * T))
    eps = 1e-9 * scale
    prev = np.inf
    for _ in range(n_iter_max):
        M = X1 @ _khatri_rao(b, c)
        _hals_update(a, M, (b.T @ b) * (c.T @ c), eps)
        M = X2 @ _khatri_rao(a, c)
        _hals_update(b, M, (a.T @ a) * (c.T @ c), eps)
        M = X3 @ _khatri_rao(a, b)
        G = (a.T @ a) * (b.T @ b)
        _hals_update(c, M, G, eps)
        # |T - T_hat|^2 = |T|^2 - 2 <T, T_hat> + |T_hat|^2, all from M and G (no reconstruction)
        err2 = normT2 - 2.0 * np.sum(M * c) + np.sum(G * (c.T @ c))
        err = np.sqrt(max(err2, 0.0) / normT2)
        if prev - err < tol * err:  # relative to err: the bake's fits sit near 1e-3
            break
        prev = err
        # keep the three factors at comparable scales (HALS is scale-sensitive)
        na, nb_, nc = (np.linalg.norm(f, axis=0) for f in (a, b, c))
        g = np.cbrt(na * nb_ * nc)
        ok = g > 0
        a[:, ok] *= g[ok] / na[ok]
        b[:, ok] *= g[ok] / nb_[ok]
        c[:, ok] *= g[ok] / nc[ok]
    return a, b, c


@numba.njit(fastmath=FASTMATH, cache=True, nogil=True)
def _hals_columns(F, M, G, eps, pad, tiny, sweeps):
    """``sweeps`` HALS sweeps over the columns of every ``F[g] (rows, R)`` in place, for
    ``min |X_g - F_g W_g^T|`` with ``M = X W`` and ``G = W^T W`` (symmetric), floored at
    ``eps[g]``; rows with ``pad[g, k]`` stay zero. Compiled (without the GIL: the bake runs cells
    in threads) because the column loop is sequential: as NumPy it was ~R small operations per
    mode and iteration."""
    n, rows, R = F.shape
    for g in range(n):
        for it in range(sweeps * R):
            r = it % R
            d = max(G[g, r, r], tiny)
            Gr = G[g, r]  # G is symmetric: its row r is column r, contiguous (a SIMD dot product)
            for k in range(rows):
                if pad[g, k]:
                    F[g, k, r] = 0.0
                    continue
                Fk = F[g, k]
                acc = M[g, k, r]
                for q in range(R):
                    acc -= Fk[q] * Gr[q]
                v = F[g, k, r] + acc / d
                F[g, k, r] = v if v > eps[g] else eps[g]


def nn_cp_batch(tensors: list[np.ndarray], rank: int, *, n_iter_max: int = 100,
                tol: float = 1e-5, seed: int = 0, init: list | None = None,
                dtype=np.float32) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """:func:`nn_cp` (method ``"hals"``) of many small ``(I, J, K_g)`` tensors at once.

    The tensors are zero-padded to a common ``K`` and updated together with batched matrix
    products, so the Python overhead per iteration is paid once per batch instead of once per
    group (a bake has thousands of groups). Padding rows of ``c`` only fit zeros and are dropped.

    ``init``: optional ``(a (I, r0), b (J, r0), c (K_g, r0))`` per tensor, ``r0 <= rank`` (a
    lower-rank fit): its terms start the first ``r0`` components (warm start), the others start
    random at a tenth of the usual scale, so the fit starts near the lower-rank optimum.

    ``dtype``: of the iterations. float32 halves the time of the batched products (they are the
    cost) and changed the error of a rank-24 fit of a level-0 cell of the 512^2 gaussian map from
    5.237 % to 5.255 %; the returned factors and errors are float64 (computed against the
    float64 tensors).
    """
    if not tensors:
        return []
    R = as_positive_int(rank, "rank")
    I, J = tensors[0].shape[:2]
    Ks = [t.shape[2] for t in tensors]
    Km = max(Ks)
    n = len(tensors)
    T = np.zeros((n, I, J, Km), dtype)
    for g, t in enumerate(tensors):
        T[g, :, :, : t.shape[2]] = t
    rng = np.random.default_rng(seed)
    norms = np.sqrt(np.einsum("gijk,gijk->g", T, T))
    normT2 = np.maximum(norms**2, 1e-300)
    scale = (np.maximum(norms, 1e-300) / np.sqrt(I * J * np.array(Ks))) ** (1.0 / 3.0)
    a = (rng.random((n, I, R)) * scale[:, None, None]).astype(dtype)
    b = (rng.random((n, J, R)) * scale[:, None, None]).astype(dtype)
    c = (rng.random((n, Km, R)) * scale[:, None, None]).astype(dtype)
    pad = np.arange(Km)[None, :] >= np.array(Ks)[:, None]
    if init is not None:
        if len(init) != n:
            raise PrefilterError(f"init: expected {n} factor triples, got {len(init)}")
        a *= 0.1
        b *= 0.1
        c *= 0.1
        for g, (ag, bg, cg) in enumerate(init):
            r0 = ag.shape[1]
            if r0 > R or bg.shape != (J, r0) or ag.shape != (I, r0) or cg.shape != (Ks[g], r0):
                raise PrefilterError(f"init: expected factors (I, r0), (J, r0), (K, r0) with "
                                     f"r0 <= {R} for tensor {g}")
            # a, b sum to 1 per column: spread the weight over the three modes like the init
            w = np.cbrt(np.maximum(cg.max(axis=0), 0.0) * ag.max(axis=0) * bg.max(axis=0))
            sa = np.where(ag.max(axis=0) > 0, w / np.maximum(ag.max(axis=0), 1e-300), 0.0)
            sb = np.where(bg.max(axis=0) > 0, w / np.maximum(bg.max(axis=0), 1e-300), 0.0)
            a[g, :, :r0] = ag * sa
            b[g, :, :r0] = bg * sb
            c[g, : Ks[g], :r0] = cg / np.maximum(sa * sb, 1e-300) * (sa * sb > 0)
    c[pad] = 0.0
    eps = (1e-9 * scale)[:, None]
    tiny = np.finfo(dtype).tiny
    X12 = T.reshape(n, I * J, Km)  # Y = X12 @ c serves the MTTKRPs of modes a and b

    def kr(x, y):
        return (x[:, :, None, :] * y[:, None, :, :]).reshape(n, -1, R)

    def gram(x):
        return np.matmul(x.transpose(0, 2, 1), x)

    no_pad = np.zeros((n, max(I, J)), bool)

    def update(F, M, G, mask=None):
        _hals_columns(F, np.ascontiguousarray(M, dtype=dtype),
                      np.ascontiguousarray(G, dtype=dtype), eps[:, 0].astype(dtype),
                      no_pad if mask is None else mask, tiny, HALS_SWEEPS)

    prev = np.full(n, np.inf)
    err = np.ones(n)
    for _ in range(n_iter_max):
        Y = np.matmul(X12, c).reshape(n, I, J, R)
        gc = gram(c)
        update(a, np.einsum("gijr,gjr->gir", Y, b), gram(b) * gc)
        update(b, np.einsum("gijr,gir->gjr", Y, a), gram(a) * gc)
        M = np.matmul(kr(a, b).transpose(0, 2, 1), X12).transpose(0, 2, 1)
        G = gram(a) * gram(b)
        update(c, M, G, pad)
        err2 = normT2 - 2.0 * np.einsum("gkr,gkr->g", M, c) + np.einsum("grs,grs->g", G, gram(c))
        err = np.sqrt(np.maximum(err2, 0.0) / normT2)
        if np.all(prev - err < tol * err):
            break
        prev = err
        na, nb_, nc = (np.linalg.norm(f, axis=1) for f in (a, b, c))
        g = np.cbrt(na * nb_ * nc)
        ok = g > 0
        for f, nf in ((a, na), (b, nb_), (c, nc)):
            f *= np.where(ok, g / np.where(nf > 0, nf, 1.0), 1.0)[:, None, :]
    out = []
    for g, t in enumerate(tensors):
        ag, bg, cg = (np.asarray(f, np.float64) for f in (a[g], b[g], c[g, : Ks[g]]))
        out.append(_normalised(ag, bg, cg, t))
    return out


def _normalised(a, b, c, T):
    sa, sb = a.sum(axis=0), b.sum(axis=0)
    live = (sa > 0) & (sb > 0)
    a = np.where(live, a / np.where(live, sa, 1.0), 0.0)
    b = np.where(live, b / np.where(live, sb, 1.0), 0.0)
    c = np.where(live, c * sa * sb, 0.0)
    norm = np.linalg.norm(T)
    err = float(np.linalg.norm(T - reconstruct(a, b, c)) / norm) if norm > 0 else 0.0
    return a, b, c, err


def exact_cp(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Exact non-negative CP ``a (I, r)``, ``b (J, r)`` (columns summing to 1), ``c (K, r)`` and
    its error (0 up to rounding) of ``tensor (I, J, K) >= 0``: one rank-one term per non-zero
    fibre of the smallest of its three fibre sets (``T = sum_ij e_i (x) e_j (x) T[i, j, :]``
    and the two other orders), so ``r <= min(I J, I K, J K)``: a group's non-negative CP rank
    never exceeds ``B^2`` (nor ``B K``). Used for the pyramid levels a bake stores exactly
    (``bake(exact_from_level=...)``)."""
    T = np.asarray(tensor, dtype=np.float64)
    if T.ndim != 3 or np.any(T < 0) or not np.all(np.isfinite(T)):
        raise PrefilterError("tensor: expected a finite non-negative (I, J, K) array")
    I, J, K = T.shape
    nz = [T.any(axis=2), T.any(axis=1), T.any(axis=0)]  # (I, J), (I, K), (J, K)
    form = int(np.argmin([m.sum() for m in nz]))
    idx = np.nonzero(nz[form])
    r = len(idx[0])
    a, b, c = np.zeros((I, r)), np.zeros((J, r)), np.zeros((K, r))
    cols = np.arange(r)
    if form == 0:
        a[idx[0], cols] = 1.0
        b[idx[1], cols] = 1.0
        c[:] = T[idx[0], idx[1], :].T
    else:
        fib = T[idx[0], :, idx[1]] if form == 1 else T[:, idx[0], idx[1]].T  # (r, J) / (r, I)
        s = fib.sum(axis=1)
        if form == 1:
            a[idx[0], cols] = 1.0
            b[:] = (fib / s[:, None]).T
        else:
            a[:] = (fib / s[:, None]).T
            b[idx[0], cols] = 1.0
        c[idx[1], cols] = s
    return _normalised(a, b, c, T)


def reconstruct(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``T_hat (I, J, K) = sum_r a_r (x) b_r (x) c_r``."""
    return (_khatri_rao(a, b) @ c.T).reshape(a.shape[0], b.shape[0], c.shape[0])


def prefix_sums(f: np.ndarray) -> np.ndarray:
    """1D prefix sums ``(R, n + 1)`` of factor columns ``f (n, R)``, starting at 0."""
    out = np.zeros((f.shape[1], f.shape[0] + 1))
    np.cumsum(f.T, axis=1, out=out[:, 1:])
    return out


def allocate_ranks(err2: np.ndarray, unit_bytes: np.ndarray, base: int, candidates,
                   budget: float, p: float = 2.0) -> np.ndarray:
    """Ranks per group that minimise the predicted total squared error under a storage budget.

    Group ``g`` was fitted at rank ``base`` with squared error ``err2[g]``; at rank ``r`` its
    error is predicted as ``err2[g] (r / base)^-p`` (``p = 2`` is the median slope measured on
    NDF blocks of the 512^2 gaussian map, ranks 8-32) and it costs ``r unit_bytes[g]`` bytes.
    Each group takes the candidate rank minimising ``error + lambda bytes``, with the smallest
    ``lambda`` (bisection) whose total is within ``budget``: the Lagrangian relaxation of the
    knapsack, optimal among allocations of at most the bytes it uses (the greedy "largest error
    drop per byte first" with convex curves).

    Parameters
    ----------
    err2 : (G,) squared errors at rank ``base``.
    unit_bytes : (G,) bytes per rank of each group.
    base : rank of the fit that measured ``err2``; candidates below it are ignored.
    candidates : ranks a group may take (``base`` is always one).
    budget : total bytes; at least ``base * unit_bytes.sum()`` is used whatever it is.

    Returns
    -------
    (G,) int ranks.
    """
    return ranks_for(err2, unit_bytes, base, candidates,
                     budget_multiplier(err2, unit_bytes, base, candidates, budget, p), p)


def _rank_costs(err2, unit_bytes, base, candidates, p):
    e = np.asarray(err2, dtype=np.float64)
    u = np.asarray(unit_bytes, dtype=np.float64)
    cand = np.unique(np.array([base] + [int(r) for r in candidates if int(r) >= base]))
    pred = e[:, None] * (cand[None, :] / base) ** (-float(p))  # (G, n)
    return e, u, cand, pred, u[:, None] * cand[None, :]


def ranks_for(err2: np.ndarray, unit_bytes: np.ndarray, base: int, candidates, lam: float,
              p: float = 2.0) -> np.ndarray:
    """Ranks ``(G,)`` minimising ``err2 (r / base)^-p + lam r unit_bytes`` per group over the
    candidates (:func:`allocate_ranks` for a given multiplier ``lam``)."""
    _, _, cand, pred, cost = _rank_costs(err2, unit_bytes, base, candidates, p)
    return cand[np.argmin(pred + float(lam) * cost, axis=1)]


def budget_multiplier(err2: np.ndarray, unit_bytes: np.ndarray, base: int, candidates,
                      budget: float, p: float = 2.0) -> float:
    """The multiplier ``lambda`` of :func:`allocate_ranks`: the smallest (bisection) whose ranks
    (:func:`ranks_for`) use at most ``budget`` bytes; 0 when every group fits at its largest
    useful rank. A one-pass bake estimates it from a sample of groups and gives each group its
    rank as soon as the group is fitted."""
    e, u, cand, pred, cost = _rank_costs(err2, unit_bytes, base, candidates, p)

    def choose(lam):
        return np.argmin(pred + lam * cost, axis=1)

    def used(j):
        return cost[np.arange(len(e)), j].sum()

    if used(choose(0.0)) <= budget:
        return 0.0
    lo, hi = 0.0, max(float(e.max()) / max(float(u[u > 0].min(initial=1.0)), 1e-300), 1e-300)
    while used(choose(hi)) > budget and hi < 1e300:
        hi *= 4.0
    for _ in range(100):  # bisection in lambda: bytes used are non-increasing in it
        mid = 0.5 * (lo + hi)
        if used(choose(mid)) > budget:
            lo = mid
        else:
            hi = mid
    return hi
