"""Footprint pyramid (filtering == direct P-NDF, interpolation weights) and non-negative CP."""

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints import pndf_image
from prefilter.glints.cp import cut_blocks, nn_cp, nn_cp_batch, prefix_sums, reconstruct
from prefilter.glints.pyramid import (interp_weights, level_difference, next_level, next_level_rows,
                                     plan)


def test_filtered_levels_equal_the_direct_pndf():
    nm = sinusoid(32, ax=0.25, ay=0.2, px=16, py=8)
    pyr = plan(32, 32, 4)
    assert pyr.n_levels == 4
    R, S = 16, 0.4
    level = pndf_image(nm, pyr.centers(0), pyr.sigma(0), R, S).astype(np.float32)
    for lv in range(1, pyr.n_levels):
        level = next_level(level, 1.0)
        direct = pndf_image(nm, pyr.centers(lv), pyr.sigma(lv), R, S)
        assert np.linalg.norm(level - direct) / np.linalg.norm(direct) < 1e-3


@pytest.mark.parametrize("ny, nx, sos", [(16, 8, 1.0), (4, 6, 1.0), (8, 8, 0.5)])
def test_next_level_rows_is_next_level_bit_for_bit(ny, nx, sos):
    """The streamed filter (rows read one at a time, few of them in memory) gives the same
    float32 images as the whole-level one, also when the filter wraps around the grid."""
    rng = np.random.default_rng(ny + nx)
    level = (rng.random((ny, nx, 5, 5)) ** 4).astype(np.float32)
    got = np.full((ny // 2, nx // 2, 5, 5), np.nan, np.float32)
    reads = []

    def read_row(y):
        reads.append(y)
        return level[y]

    def write_row(yo, images):
        got[yo] = images

    next_level_rows(read_row, (ny, nx), sos, write_row, (5, 5))
    np.testing.assert_array_equal(got, next_level(level, sos))
    assert len(reads) <= ny + 15  # each row once, the wrapped ones at most once more


def test_interp_weights_hit_the_samples_and_sum_to_one():
    pyr = plan(64, 64, 4)
    c = pyr.centers(2)[1, 3]
    idx, w = interp_weights(pyr, c, pyr.sigma(2))
    assert idx[np.argmax(w)] == pyr.offsets[2] + 1 * pyr.shape(2)[1] + 3
    assert w.max() == pytest.approx(1.0)
    rng = np.random.default_rng(0)
    idx, w = interp_weights(pyr, rng.uniform(-100, 100, (50, 2)), rng.uniform(0, 200, 50))
    np.testing.assert_allclose(w.sum(-1), 1.0)
    assert np.all(w >= 0) and np.all((idx >= 0) & (idx < pyr.n_images))


def test_interp_is_linear_in_position_and_log_sigma():
    """Interpolating a quantity linear in (x, y, log2 sigma) on the sample grid is exact."""
    pyr = plan(64, 64, 4)
    val = np.concatenate([
        (pyr.centers(lv)[..., 0] + 2 * pyr.centers(lv)[..., 1] + 5 * lv).ravel()
        for lv in range(pyr.n_levels)])
    c = np.array([[10.0, 12.0], [20.3, 7.9]])
    sp = np.array([4 * 2**0.3, 8 * 2**0.5])
    idx, w = interp_weights(pyr, c, sp)
    got = (val[idx] * w).sum(-1)
    np.testing.assert_allclose(got, c[:, 0] + 2 * c[:, 1] + 5 * np.log2(sp / 4), atol=1e-9)


def test_level_difference_and_plan_errors():
    a = np.ones((4, 4, 2, 2))
    assert level_difference(a, a[::2, ::2]) == 0.0
    with pytest.raises(PrefilterError, match="stride0"):
        plan(30, 30, 4)


def exact_tensor(rank=4, shape=(8, 8, 40), seed=0):
    rng = np.random.default_rng(seed)
    a, b, c = (rng.random((n, rank)) for n in shape)
    return reconstruct(a, b, c)


@pytest.mark.parametrize("method", ["hals", "tensorly"])
def test_nn_cp_recovers_an_exact_nonnegative_tensor(method):
    T = exact_tensor()
    a, b, c, err = nn_cp(T, 4, n_iter_max=2000, tol=1e-12, method=method)
    assert err < 2e-2
    assert np.linalg.norm(reconstruct(a, b, c) - T) / np.linalg.norm(T) == pytest.approx(err)
    assert min(a.min(), b.min(), c.min()) >= 0
    np.testing.assert_allclose(a.sum(0), 1.0)
    np.testing.assert_allclose(b.sum(0), 1.0)


def test_hals_reaches_tensorly_error_on_ndf_blocks():
    nm = sinusoid(32, ax=0.25, ay=0.2, px=16, py=8)
    pyr = plan(32, 32, 4)
    imgs = pndf_image(nm, pyr.centers(0), 4.0, 32, 0.4).reshape(-1, 32, 32)
    T = np.ascontiguousarray(cut_blocks(imgs, 8)[:, 1, 2].transpose(1, 2, 0))
    e_tl = nn_cp(T, 6, n_iter_max=300, tol=1e-7, method="tensorly")[3]
    e_batch = nn_cp_batch([T, T[:, :, :20]], 6, n_iter_max=300, tol=1e-7)[0][3]
    # measured on this map's central blocks: ours 0.34-0.37 %, tensorly's 0.13-0.23 % (one HALS
    # sweep per product, cp.HALS_SWEEPS, stops further from the minimum); both far below the
    # percent-level errors the bakes allocate ranks by
    assert e_batch < e_tl + 2e-3, (e_batch, e_tl)
    assert e_batch < 5e-3


def test_prefix_sums_and_blocks():
    f = np.arange(6.0).reshape(3, 2)
    np.testing.assert_allclose(prefix_sums(f), [[0, 0, 2, 6], [0, 1, 4, 9]])
    img = np.arange(16.0).reshape(4, 4)
    blk = cut_blocks(img, 2)
    np.testing.assert_array_equal(blk[1, 0], [[8, 9], [12, 13]])


def test_allocate_ranks_is_optimal_for_the_bytes_it_uses():
    """Brute force over all allocations of a small problem: none within the same bytes has a
    smaller predicted error, and the budget is respected."""
    import itertools

    from prefilter.glints.cp import allocate_ranks

    rng = np.random.default_rng(0)
    base, cand, p = 4, [4, 6, 8, 12], 2.0
    for _ in range(5):
        e = rng.random(5) ** 3 * 10
        u = rng.integers(5, 60, 5).astype(float)
        budget = rng.uniform(4.5, 11) * u.sum()
        r = allocate_ranks(e, u, base, cand, budget, p)
        used = float(u @ r)
        assert used <= budget + 1e-9
        pred = float(np.sum(e * (r / base) ** -p))
        best = min(np.sum(e * (np.array(c) / base) ** -p)
                   for c in itertools.product(cand, repeat=5) if u @ np.array(c) <= used + 1e-9)
        assert pred <= best * (1 + 1e-12)
    # a budget below the base rank keeps everything at the base; a huge one takes the maximum
    np.testing.assert_array_equal(allocate_ranks(e, u, base, cand, 0.0, p), base)
    np.testing.assert_array_equal(allocate_ranks(e, u, base, cand, 1e9, p), 12)


def test_nn_cp_batch_warm_start():
    """Started from the exact factors of a rank-4 tensor, HALS stays there; bad shapes fail."""
    rng = np.random.default_rng(1)
    a, b, c = (rng.random((n, 4)) for n in (8, 8, 30))
    T = reconstruct(a, b, c)
    cold = nn_cp_batch([T], 4, n_iter_max=3, tol=0)[0][3]
    warm = nn_cp_batch([T], 4, n_iter_max=3, tol=0, init=[(a, b, c)])[0][3]
    assert warm < 1e-6 < cold
    # extra components start small: the fit stays close to the exact one
    assert nn_cp_batch([T], 6, n_iter_max=3, tol=0, init=[(a, b, c)])[0][3] < 0.05
    with pytest.raises(PrefilterError, match="init"):
        nn_cp_batch([T], 3, init=[(a, b, c)])


def test_split_budget_per_level_and_uniform():
    """``level_rank="level"``: every level's groups spend at most ``rank`` per byte on average
    (its own budget; the same total as the map-wide split) and each level's split is the
    map-wide optimum restricted to that level; ``"uniform"``: every group at ``rank``."""
    from prefilter.glints.bake import split_budget
    from prefilter.glints.cp import allocate_ranks

    rng = np.random.default_rng(3)
    G, rank, base, cand = 300, 8, 4, [4, 6, 8, 12, 16, 24]
    level = np.repeat([0, 1, 2], [200, 70, 30])
    # level 0 holds most of the error, as in a baked map: the map-wide split favours it
    e = rng.random(G) ** 3 * np.where(level == 0, 50.0, 1.0)
    u = rng.integers(5, 100, G).astype(float)
    glob = split_budget(e, u, level, rank, base, cand, "global")
    per = split_budget(e, u, level, rank, base, cand, "level")
    np.testing.assert_array_equal(glob, allocate_ranks(e, u, base, cand, rank * u.sum()))
    means_glob, means_per = [], []
    for lv in range(3):
        s = level == lv
        np.testing.assert_array_equal(per[s], allocate_ranks(e[s], u[s], base, cand,
                                                             rank * u[s].sum()))
        assert u[s] @ per[s] <= rank * u[s].sum() + 1e-9
        means_glob.append(u[s] @ glob[s] / u[s].sum())
        means_per.append(u[s] @ per[s] / u[s].sum())
    assert u @ per <= rank * u.sum() + 1e-9
    # the map-wide split is uneven across the levels; the per-level one within 15 % of rank
    assert max(means_glob) - min(means_glob) > 0.3 * rank
    assert min(means_per) > 0.85 * rank
    np.testing.assert_array_equal(split_budget(e, u, level, rank, base, cand, "uniform"), rank)


@pytest.mark.parametrize("shape", [(4, 4, 30), (4, 5, 2), (3, 8, 8)])
def test_exact_cp_reconstructs_and_bounds_the_rank(shape):
    """cp.exact_cp: reconstruction == the tensor (float rounding), a / b columns sum to 1, rank
    <= min(IJ, IK, JK) and no larger than the number of non-zero fibres; sparse tensors (most
    fibres zero) get fewer terms; an all-zero tensor gives rank 0."""
    from prefilter.glints.cp import exact_cp, reconstruct

    rng = np.random.default_rng(11)
    I, J, K = shape
    T = rng.random(shape) * (rng.random(shape) < 0.3)
    a, b, c, err = exact_cp(T)
    r = a.shape[1]
    assert r <= min(I * J, I * K, J * K)
    assert r == min((T.any(axis=2)).sum(), (T.any(axis=1)).sum(), (T.any(axis=0)).sum())
    np.testing.assert_allclose(reconstruct(a, b, c), T, atol=1e-14)
    assert err < 1e-14 and np.all(a >= 0) and np.all(b >= 0) and np.all(c >= 0)
    np.testing.assert_allclose(a.sum(axis=0), 1.0)
    np.testing.assert_allclose(b.sum(axis=0), 1.0)
    assert exact_cp(np.zeros(shape))[0].shape == (I, 0)


@pytest.mark.parametrize("ny, nx", [(16, 8), (4, 4), (2, 2), (8, 16)])
def test_level_stream_is_next_level_in_any_order(tmp_path, ny, nx):
    """The streamed filter (rows in any order, in runs of columns, accumulators spilled to
    files) gives :func:`next_level`'s images to float32 rounding and the level difference."""
    from prefilter.glints.pyramid import LevelStream, level_difference, next_level

    rng = np.random.default_rng(0)
    L = rng.random((ny, nx, 8, 8)).astype(np.float32)
    ref = next_level(L, 1.0)
    st = LevelStream((ny, nx), 1.0, (8, 8), spill_dir=tmp_path)
    got = {}
    for y in list(range(2, ny)) + [0, 1]:
        h = nx // 2 + 1 if nx > 2 else 1
        st.add(y, 0, L[y, :h])
        st.add(y, h, L[y, h:])
        for yo, row in st.arrived([y]):
            got[yo] = row
        st.spill()
    out = np.stack([got[i] for i in range(ny // 2)])
    assert np.abs(out - ref).max() <= 2e-6 * ref.max()
    assert st.difference == pytest.approx(level_difference(L, ref), rel=1e-4)  # float16 even images
    assert not list(tmp_path.iterdir())


def test_budget_multiplier_gives_allocate_ranks():
    from prefilter.glints.cp import allocate_ranks, budget_multiplier, ranks_for

    rng = np.random.default_rng(3)
    e, u = rng.random(200) ** 3, rng.integers(10, 40, 200).astype(float)
    for budget in (8 * u.sum(), 12 * u.sum(), 100 * u.sum()):
        lam = budget_multiplier(e, u, 8, [8, 12, 16, 24], budget)
        assert np.array_equal(ranks_for(e, u, 8, [8, 12, 16, 24], lam),
                              allocate_ranks(e, u, 8, [8, 12, 16, 24], budget))
