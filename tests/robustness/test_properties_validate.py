"""Property-based tests of the shared input checks (prefilter.validation), used at every public
boundary: what passes is returned unchanged as float64, everything else is a PrefilterError
naming the parameter."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from prefilter.validation import (
    as_directions,
    as_float_array,
    as_positive_int,
    as_rng,
    as_roughness,
    as_uniform,
    as_upper_directions,
    broadcast_batch,
)
from prefilter.errors import PrefilterError

N = settings.default.max_examples

shapes = hnp.array_shapes(min_dims=0, max_dims=3, max_side=4)
numeric = st.sampled_from([np.float64, np.float32, np.int32, np.uint8])


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert str(err.value).startswith(name + ":"), str(err.value)


@settings(max_examples=N)
@given(hnp.arrays(numeric, shapes, elements=st.integers(0, 100)))
def test_finite_numeric_arrays_pass_unchanged(a):
    out = as_float_array(a, "x")
    assert out.dtype == np.float64 and out.shape == a.shape
    assert np.array_equal(out, a.astype(np.float64))


@settings(max_examples=N)
@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3, max_side=4),
                  elements=st.floats(-10, 10)), st.data())
def test_any_nan_or_inf_is_refused(a, data):
    idx = tuple(data.draw(st.integers(0, n - 1)) for n in a.shape)
    a[idx] = data.draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    expect_error(lambda: as_float_array(a, "thing"), "thing")


@pytest.mark.parametrize("bad", [None, "0.5", b"1", 1 + 2j, np.array([1 + 0j]), [1, None],
                                 [[1, 2], [3]], {"a": 1}, object()])
def test_non_numbers_are_refused(bad):
    # NumPy would parse "0.5", drop imaginary parts and turn None into NaN
    expect_error(lambda: as_float_array(bad, "value"), "value")


@settings(max_examples=N)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(1e-4, 1.0))
def test_directions(x, y, z, tol):
    v = np.array([x, y, z])
    n = np.linalg.norm(v)
    if abs(n - 1.0) > tol:
        expect_error(lambda: as_directions(v, "w", tol=tol), "w")
    else:
        assert np.isclose(np.linalg.norm(as_directions(v, "w", tol=tol)), 1.0)
        if v[2] / n > 0:
            assert as_upper_directions(v, "w", tol=tol)[2] > 0
        else:
            expect_error(lambda: as_upper_directions(v, "w", tol=tol), "w")


@settings(max_examples=N)
@given(st.one_of(st.floats(-10, 10), st.sampled_from([np.nan, np.inf, -np.inf])))
@example(1e-4)
@example(4.0)
def test_roughness_and_uniforms(a):
    if 1e-4 <= a <= 4.0:
        assert as_roughness(a, "alpha") == a
    else:
        expect_error(lambda: as_roughness(a, "alpha"), "alpha")
    if 0.0 <= a <= 1.0:
        assert as_uniform([a, a], "u", last_dim=2).shape == (2,)
    else:
        expect_error(lambda: as_uniform([a, a], "u", last_dim=2), "u")


def test_integers_seeds_and_batches():
    assert as_positive_int(np.int64(3), "n") == 3
    for bad in (0, -1, 2.0, True, "3", None):
        expect_error(lambda: as_positive_int(bad, "n"), "n")
    assert isinstance(as_rng(5), np.random.Generator)
    for bad in (None, 1.5, "seed", True):
        expect_error(lambda: as_rng(bad, "seed"), "seed")
    assert broadcast_batch(a=(3, 1), b=(4,)) == (3, 4)
    expect_error(lambda: broadcast_batch(a=(3,), b=(4,)), "a, b")


@pytest.mark.parametrize("seed", [-1, -3, np.int64(-7), -(10**30)])
def test_negative_seeds_are_refused(seed):
    expect_error(lambda: as_rng(seed, "seed"), "seed")


def test_integer_upper_bounds():
    assert as_positive_int(5, "n", hi=5) == 5
    expect_error(lambda: as_positive_int(10**30, "n_taps", hi=100), "n_taps")
    expect_error(lambda: as_positive_int(6, "n", hi=5), "n")
