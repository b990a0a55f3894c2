"""The compiled feature kernels' building blocks, checked against plain numpy or by simulation.

The features themselves are checked against the slow reference in test_features.py; these
tests pin down the pieces whose bugs the reference scans might not reach: the program of
complex products behind the Fourier sums (every order, every block size), the sliding
minimum, the input cleaning, odd beam counts and high Fourier orders.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from knowledge.places.features import MIN_RANGE, FeatureExtractor, parse_name
from knowledge.places.features.batch import array_max, clean_chunk, mean_std, window_min
from knowledge.places.features.fourier_plan import DOT, E_ROW, MUL, best_program, make_plan, program
from knowledge.places.features.reference import reference_features
from knowledge.places.features.synthetic import random_scans

MAX_RANGE = 30.0


def _run_program(ops: tuple[tuple[int, int, int, int], ...], rows: int) -> dict[int, int]:
    """The exponent of E each DOT op sees, by executing the program on exponents instead of
    complex rows (a product adds exponents); unset rows hold None."""
    exponent: list[int | None] = [None] * rows
    exponent[E_ROW] = 1
    seen: dict[int, int] = {}
    for kind, a, b, c in ops:
        assert 0 <= a < rows and a % 2 == 0
        if kind == MUL:
            assert 0 <= c < rows and c % 2 == 0 and c >= 4  # never over τ or E
            ea, eb = exponent[a], exponent[b]
            assert ea is not None and eb is not None
            exponent[c] = ea + eb
        else:
            assert kind == DOT
            ea = exponent[a]
            assert ea is not None
            if b >= 0:
                eb = exponent[b]
                assert eb is not None
                ea += eb
            assert c not in seen
            seen[c] = ea
    return seen


@settings(max_examples=60, deadline=None)
@given(
    orders=st.sets(st.integers(2, 400), min_size=0, max_size=30),
    block=st.integers(1, 40),
)
def test_fourier_program_makes_every_requested_power(orders: set[int], block: int) -> None:
    wanted = tuple(sorted({1, *orders}))
    ops, rows, cost = program(wanted, block)
    seen = _run_program(ops, rows)
    assert seen == dict(enumerate(wanted))
    assert cost > 0


@pytest.mark.parametrize(
    "orders",
    [(1,), (1, 2), (1, 1000), tuple(range(1, 102)), (1, 2, 3, 4, 5, 6, 11, 15, 16, 17, 50, 85, 89, 94, 95)],
)
def test_best_fourier_program_is_correct_and_small(orders: tuple[int, ...]) -> None:
    ops, rows = best_program(orders)
    assert _run_program(ops, rows) == dict(enumerate(orders))
    products = sum(op[0] == MUL for op in ops)
    # baby and giant steps: about 2√max|n| products, far fewer than max|n|
    assert products <= 2 * int(np.sqrt(orders[-1])) + 2 + len(orders)
    assert rows <= 4 + 2 * (2 * int(np.sqrt(orders[-1])) + 4 + len(orders))


def test_fourier_plan_columns() -> None:
    names = ["B.6[n=-3]", "B.7/B.8", "B.6[n=3]", "B.6[n=7]"]
    plan = make_plan([parse_name(n) for n in names], [10, 11, 12, 13])
    # orders |n| ascending, n = 1 first (needed for the normalisation)
    assert plan.order_nn.tolist() == [1.0, 9.0, 49.0]
    assert plan.order_pos.tolist() == [-1, 12, 13]
    assert plan.order_neg.tolist() == [-1, 10, -1]
    assert plan.single.tolist() == [-1, -1, 11]


@settings(max_examples=40, deadline=None)
@given(
    values=st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=1, max_size=120),
    w=st.integers(1, 40),
)
def test_window_min_is_the_sliding_minimum(values: list[float], w: int) -> None:
    src = np.array(values)
    w = min(w, src.size)
    n = src.size - w + 1
    out = np.empty(n)
    window_min(src, w, np.empty((2, src.size)), out)
    expected = np.array([src[j : j + w].min() for j in range(n)])
    np.testing.assert_array_equal(out, expected)


def test_reductions_match_numpy() -> None:
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 5, 8, 360, 1001):
        a = rng.normal(3.0, 2.0, size=n)
        assert array_max(a) == a.max()
        mean, std = mean_std(a)
        assert mean == pytest.approx(a.mean(), rel=1e-13)
        assert std == pytest.approx(a.std(), rel=1e-12, abs=1e-15)
    # two-pass: a constant array's spread is rounding only, not the cancellation of Σx² − (Σx)²/n
    assert mean_std(np.full(360, 2.7))[1] < 1e-14


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_cleaning(dtype: type[np.floating]) -> None:
    src = np.array([[np.nan, np.inf, -np.inf, 0.0, -1.0, 1e9, 5.0, 0.005, 30.0, 29.5]], dtype=dtype)
    out = np.empty(src.shape)
    clean_chunk(src, 30.0, out)
    expected = [30.0, 30.0, MIN_RANGE, MIN_RANGE, MIN_RANGE, 30.0, 5.0, MIN_RANGE, 30.0, 29.5]
    np.testing.assert_array_equal(out[0], expected)


def test_float32_input_equals_its_float64_values() -> None:
    scans, _ = random_scans(4, rng=np.random.default_rng(8), max_range=MAX_RANGE)
    s32 = scans.astype(np.float32)
    fx = FeatureExtractor(["A.1", "A.8[w=10,eps=0.05m]", "B.6[n=5]", "B.9[phi=3]"], max_range=MAX_RANGE)
    np.testing.assert_array_equal(fx(s32), fx(s32.astype(np.float64)))


@pytest.mark.parametrize("M", [7, 91, 361])
def test_odd_beam_counts_match_the_reference(M: int) -> None:
    """Odd M exercises the unpaired last element of every loop, M > 256 several blocks."""
    scans, _ = random_scans(2, rng=np.random.default_rng(M), num_beams=M, max_range=10.0)
    names = ["A.1", "A.4[maxrange=2m]", "A.9", "A.10", "A.12", "A.16", "B.4", "B.9[phi=5]", "B.7/B.8"]
    names += ["B.6[n=-2]", "B.6[n=3]"]
    if M >= 10:
        names += ["A.8[w=5,eps=0.05m]", "A.8[w=10,eps=0.1m]"]
    fast = FeatureExtractor(names, max_range=10.0, dtype=np.float64)(scans)
    ref = np.stack([reference_features(s, names, max_range=10.0) for s in scans])
    np.testing.assert_allclose(fast, ref, rtol=1e-9, atol=1e-12)


def test_high_fourier_orders_match_the_reference() -> None:
    """Orders near the accepted limit: long products of unit phasors stay accurate."""
    scans, _ = random_scans(2, rng=np.random.default_rng(12), max_range=MAX_RANGE)
    names = ["B.6[n=2]", "B.6[n=-333]", "B.6[n=640]", "B.6[n=-999]", "B.6[n=1000]"]
    fast = FeatureExtractor(names, max_range=MAX_RANGE, dtype=np.float64)(scans)
    ref = np.stack([reference_features(s, names, max_range=MAX_RANGE) for s in scans])
    np.testing.assert_allclose(fast, ref, rtol=1e-9, atol=1e-12)
    assert np.all(fast[:, 1:] > 0)


def test_chunks_do_not_change_the_result() -> None:
    scans, _ = random_scans(11, rng=np.random.default_rng(13), max_range=MAX_RANGE)
    names = ["A.2", "A.8[w=20,eps=0.02m]", "A.10", "B.5", "B.6[n=-40]", "B.9[phi=7]"]
    whole = FeatureExtractor(names, max_range=MAX_RANGE)(scans)
    for chunk in (1, 3, 10):
        np.testing.assert_array_equal(
            FeatureExtractor(names, max_range=MAX_RANGE, chunk_size=chunk)(scans), whole
        )
