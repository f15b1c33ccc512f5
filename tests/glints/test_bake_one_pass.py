"""The one-pass bake: cells fitted and refitted while their images are in memory, the coarser
levels streamed (:func:`prefilter.glints.bake.one_pass_stages`)."""

import numpy as np
import pytest
from maps import sinusoid

from prefilter.glints import bake as gbake
from prefilter.glints.bake import bake
from prefilter.glints.store import load

KW = dict(rank=4, ndf_res=16, block=8, support=0.4, cell=8, n_iter_max=10)
KW_EXACT = dict(KW, exact_from_level=2, exact_cell=1, code_bits=16, c_bits=8)


def _pickled_map(fn, *iterables):
    import pickle

    return [pickle.loads(pickle.dumps(fn))(*pickle.loads(pickle.dumps(args)))
            for args in zip(*iterables)]


def test_one_pass_keeps_the_pyramid_and_meets_about_the_budget(tmp_path):
    """Same pyramid (levels, level differences to float32 rounding) as the two-pass bake; the
    sampled multiplier spends about the budget and the error stays close."""
    nm = sinusoid(64, px=16, py=8)
    a = bake(nm, tmp_path / "two.npz", progress=False, **KW)
    b = bake(nm, tmp_path / "one.npz", progress=False, one_pass=True, **KW)
    assert load(tmp_path / "one.npz").header["settings"]["one_pass"] is True
    assert a["n_images"] == b["n_images"]
    # the one-pass difference reads float16 images (LevelStream): 4e-5 apart here at 0.002
    assert np.allclose(a["level_differences"], b["level_differences"], rtol=1e-3, atol=1e-4)
    assert abs(b["mean_rank_per_byte"] / a["mean_rank_per_byte"] - 1) < 0.25
    assert b["rel_l2_error"] < 1.5 * a["rel_l2_error"]
    assert not (tmp_path / "one.npz.parts").exists()


def test_one_pass_is_deterministic_through_any_map(tmp_path):
    """Rerun, tasks pickled and run last to first: the same bytes."""
    nm = sinusoid(32, px=16, py=8)
    bake(nm, tmp_path / "a.npz", progress=False, one_pass=True, **KW_EXACT)
    bake(nm, tmp_path / "b.npz", progress=False, one_pass=True, **KW_EXACT)
    calls = []

    def reversed_map(fn, *iterables):
        args = list(zip(*iterables))
        calls.append(fn.__name__)
        out = _pickled_map(fn, *zip(*args[::-1])) if args else []
        return out[::-1]

    bake(nm, tmp_path / "c.npz", progress=False, one_pass=True, map_fn=reversed_map,
         **KW_EXACT)
    data = [(tmp_path / f"{n}.npz").read_bytes() for n in "abc"]
    assert data[0] == data[1] == data[2]
    assert set(calls) == {"sample_cell_task", "cell_task"}


def test_one_pass_resumes_to_the_same_bytes(tmp_path, monkeypatch):
    """Killed after some cells, the bake resumes from their parts to the same bytes."""
    nm = sinusoid(32, px=16, py=8)
    bake(nm, tmp_path / "a.npz", progress=False, one_pass=True, **KW_EXACT)
    real, n = gbake.refit_cell, [0]

    class Killed(Exception):
        pass

    def dying(*args):
        n[0] += 1
        if n[0] > 5:
            raise Killed
        return real(*args)

    monkeypatch.setattr(gbake, "refit_cell", dying)
    with pytest.raises(Killed):
        bake(nm, tmp_path / "b.npz", progress=False, one_pass=True, map_fn=map, **KW_EXACT)
    monkeypatch.setattr(gbake, "refit_cell", real)
    assert len(list((tmp_path / "b.npz.parts").glob("*"))) > 0
    bake(nm, tmp_path / "b.npz", progress=False, one_pass=True, **KW_EXACT)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_one_pass_uniform_and_all_exact(tmp_path):
    """No sample when no multiplier is needed (uniform ranks, every level exact)."""
    nm = sinusoid(32, px=16, py=8)
    s = bake(nm, tmp_path / "u.npz", progress=False, one_pass=True, level_rank="uniform", **KW)
    assert set(s["rank_histogram"]) == {4}
    s = bake(nm, tmp_path / "e.npz", progress=False, one_pass=True,
             **dict(KW_EXACT, exact_from_level=0))
    assert s["rel_l2_error_fit"] < 1e-6


def test_sample_cells_spread_over_the_map():
    from prefilter.glints.pyramid import plan

    cells = gbake.cell_bounds(plan(256, 256), [8] * 7)
    ids = gbake.sample_cells(cells, 4)
    ys, xs = cells[ids, 1], cells[ids, 3]
    assert len(ids) == 4 and len(set(ys)) == 4 and len(set(xs)) == 4
    assert (cells[ids, 0] == 0).all()
    assert gbake.sample_cells(cells[:3], 4) == [0, 1, 2]


class _Direct:
    """A ``level0`` callable giving the direct P-NDF rows (what the bake computes itself: float32
    sums)."""

    key = "direct-rows"

    def __init__(self, nm, R, S):
        self.nm, self.R, self.S = nm, R, S

    def __call__(self, y, centers, sigma):
        from prefilter.glints.pndf import pndf_image

        return pndf_image(self.nm, centers, sigma, self.R, self.S, dtype=np.float32)


def test_one_pass_with_a_level0_callable_gives_the_same_codes(tmp_path):
    nm = sinusoid(32, px=16, py=8)
    bake(nm, tmp_path / "a.npz", progress=False, one_pass=True, **KW)
    bake(nm, tmp_path / "b.npz", progress=False, one_pass=True,
         level0=_Direct(nm, KW["ndf_res"], KW["support"]), **KW)
    ga, gb = load(tmp_path / "a.npz"), load(tmp_path / "b.npz")
    assert all(np.array_equal(ga.codes[k], gb.codes[k]) for k in ga.codes)


@pytest.mark.parametrize("one_pass", [True, False])
def test_every_fitted_group_gets_the_iterations_split_between_the_passes(tmp_path, monkeypatch,
                                                                         one_pass):
    """Pass 1 runs ``pass1_iters`` cold at the base rank; the final fit continues every fitted
    group (base rank too) from it for the rest, so each gets ``n_iter_max`` in all."""
    calls = []
    real = gbake.cpmod.nn_cp_batch

    def spy(tensors, rank, **kw):
        calls.append((len(tensors), rank, kw["n_iter_max"], kw.get("init") is not None))
        return real(tensors, rank, **kw)

    monkeypatch.setattr(gbake.cpmod, "nn_cp_batch", spy)
    kw = dict(KW, n_iter_max=12)
    bake(sinusoid(32, px=16, py=8), tmp_path / "m.npz", progress=False, one_pass=one_pass, **kw)
    n1 = gbake.pass1_iters(12)
    assert n1 == 6
    first = [c for c in calls if not c[3]]
    rest = [c for c in calls if c[3]]
    base = kw["rank"] // 2
    assert first and all(c[1] == base and c[2] == n1 for c in first)
    assert rest and all(c[2] == 12 - n1 for c in rest)
    assert any(c[1] == base for c in rest) and any(c[1] > base for c in rest)
    # the sample cells of a one-pass bake are fitted once in pass 1 (their part is reused)
    assert sum(c[0] for c in rest) == sum(c[0] for c in first)
