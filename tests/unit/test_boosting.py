"""Boosting (book Fig. 3.3, 4.2) and its weak learners (eq. 3.1/4.1, 5.2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.errors import NotFittedError
from knowledge.learning.boosting import DiscreteAdaBoost, GeneralizedAdaBoost, booster_from_state
from knowledge.learning.weak import KIND_INTERVAL, KIND_THRESHOLD, SortedFeatures

# -- brute force references -------------------------------------------------------------


def cut_points(values: np.ndarray) -> np.ndarray:
    """Midpoints between consecutive distinct values."""
    u = np.unique(values)
    return (u[:-1] + u[1:]) / 2


def brute_threshold(X: np.ndarray, D: np.ndarray, pos: np.ndarray) -> float:
    """Smallest weighted error Σ D |h − y| over every feature, cut and polarity (eq. 3.2)."""
    best = math.inf
    for f in range(X.shape[1]):
        for theta in cut_points(X[:, f]):
            for p in (1, -1):
                h = p * X[:, f] < p * theta
                best = min(best, float(D[h != pos].sum()))
    return best


def brute_interval(X: np.ndarray, D: np.ndarray, pos: np.ndarray) -> float:
    """Smallest weighted error over every interval (open ends allowed, not both) and sign."""
    best = math.inf
    for f in range(X.shape[1]):
        cuts = np.concatenate([[-np.inf], cut_points(X[:, f]), [np.inf]])
        for i in range(len(cuts)):
            for j in range(i + 1, len(cuts)):
                if i == 0 and j == len(cuts) - 1:
                    continue
                inside = (X[:, f] > cuts[i]) & (X[:, f] < cuts[j])
                for p in (True, False):
                    h = inside if p else ~inside
                    best = min(best, float(D[h != pos].sum()))
    return best


def random_problem(rng: np.random.Generator, style: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted data: continuous, rounded (ties among many values) or coarse (few values)."""
    N = int(rng.integers(8, 60))
    F = int(rng.integers(1, 4))
    if style == "continuous":
        X = rng.normal(size=(N, F))
    elif style == "rounded":
        X = np.round(rng.normal(size=(N, F)), 1)
    else:
        X = rng.integers(0, 4, size=(N, F)).astype(float)
    pos = rng.random(N) < rng.uniform(0.2, 0.8)
    D = rng.random(N) ** 2
    D /= D.sum()
    return X, D, pos


def weighted_error(learner_h: np.ndarray, D: np.ndarray, pos: np.ndarray) -> float:
    return float(D[(learner_h > 0) != pos].sum())


# -- the weak learner search ------------------------------------------------------------


@pytest.mark.parametrize("style", ["continuous", "rounded", "coarse"])
def test_threshold_search_equals_brute_force(style: str) -> None:
    rng = np.random.default_rng(7)
    for _ in range(25):
        X, D, pos = random_problem(rng, style)
        if all(np.unique(X[:, f]).size < 2 for f in range(X.shape[1])):
            continue
        ws = D * np.where(pos, 1.0, -1.0)
        learner = SortedFeatures(X).best(ws, np.zeros(X.shape[1], dtype=bool))
        assert learner is not None and learner.kind == KIND_THRESHOLD
        expected = brute_threshold(X, D, pos)
        h = learner.predict(X[:, learner.feature])
        assert weighted_error(h, D, pos) == pytest.approx(expected, abs=1e-12)
        assert (1 - learner.r) / 2 == pytest.approx(expected, abs=1e-12)
        # the threshold lies strictly between two distinct training values
        assert not np.any(X[:, learner.feature] == learner.threshold)


@pytest.mark.parametrize("style", ["continuous", "rounded", "coarse"])
def test_interval_search_equals_brute_force(style: str) -> None:
    rng = np.random.default_rng(11)
    for _ in range(15):
        X, D, pos = random_problem(rng, style)
        if all(np.unique(X[:, f]).size < 2 for f in range(X.shape[1])):
            continue
        ws = D * np.where(pos, 1.0, -1.0)
        learner = SortedFeatures(X).best(ws, np.ones(X.shape[1], dtype=bool))
        assert learner is not None and learner.kind == KIND_INTERVAL
        expected = brute_interval(X, D, pos)
        h = learner.predict(X[:, learner.feature])
        assert weighted_error(h, D, pos) == pytest.approx(expected, abs=1e-12)
        assert (1 - learner.r) / 2 == pytest.approx(expected, abs=1e-12)


def test_sort_splits_fine_and_coarse_features() -> None:
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.normal(size=400), rng.integers(0, 5, 400), np.full(400, 2.0)])
    sf = SortedFeatures(X)
    assert sf.coarse.tolist() == [False, True, True]
    assert sf.nbytes > 0
    # a constant feature can never be chosen
    ws = rng.normal(size=400) / 400
    learner = sf.best(ws, np.zeros(3, dtype=bool))
    assert learner is not None and learner.feature in (0, 1)


def test_sort_rows_of_mixed_features() -> None:
    rng = np.random.default_rng(1)
    N = 240
    cols = [
        rng.integers(0, 3, N),
        rng.normal(size=N),
        rng.integers(0, 9, N),
        rng.normal(size=N),
        np.round(rng.normal(size=N), 2),
    ]
    X = np.column_stack(cols).astype(float)
    sf = SortedFeatures(X)
    assert sf.coarse.tolist() == [True, False, True, False, False]
    for f in sf.fine_features:
        assert (np.diff(X[sf.order[sf.row[f]], f]) >= 0).all()
    for f in sf.coarse_features:
        values = np.unique(X[:, f])
        np.testing.assert_array_equal(values[sf.ranks[sf.row[f]]], X[:, f])
    D = rng.random(N)
    D /= D.sum()
    pos = rng.random(N) < 0.5
    learner = sf.best(D * np.where(pos, 1.0, -1.0), np.zeros(5, dtype=bool))
    assert learner is not None
    assert (1 - learner.r) / 2 == pytest.approx(brute_threshold(X, D, pos), abs=1e-12)


def test_interval_learner_finds_a_planted_interval() -> None:
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 10, size=600)
    X = np.column_stack([rng.normal(size=600), x, rng.uniform(0, 10, size=600)])
    y = (x > 3.0) & (x < 6.0)
    model = GeneralizedAdaBoost(5, weak="interval").fit(X, y)
    assert model.weak_feature_[0] == 1 and model.weak_kind_[0] == KIND_INTERVAL
    assert model.weak_polarity_[0] == 1
    inside = np.sort(x[y])
    outside_lo, outside_hi = x[x <= 3.0].max(), x[x >= 6.0].min()
    assert outside_lo < model.weak_threshold_[0] < inside[0]
    assert inside[-1] < model.weak_upper_[0] < outside_hi
    assert model.stop_reason_ == "perfect" and model.n_rounds_ == 1
    assert model.train_error_ == 0.0
    # thresholds alone need at least two learners for the same data
    assert GeneralizedAdaBoost(1).fit(X, y).train_error_ > 0


def test_per_feature_weak_choice() -> None:
    rng = np.random.default_rng(4)
    x = rng.integers(0, 8, size=500).astype(float)
    X = np.column_stack([x, x])
    y = (x > 2) & (x < 5)
    by_name = GeneralizedAdaBoost(1, weak=["threshold", "interval"]).fit(X, y)
    assert by_name.weak_feature_[0] == 1 and by_name.weak_kind_[0] == KIND_INTERVAL
    mask = GeneralizedAdaBoost(1, weak=np.array([True, False])).fit(X, y)
    assert mask.weak_feature_[0] == 0 and mask.weak_kind_[0] == KIND_INTERVAL
    with pytest.raises(ValueError, match="one entry per feature"):
        GeneralizedAdaBoost(1, weak=["threshold"]).fit(X, y)
    with pytest.raises(ValueError, match="threshold"):
        GeneralizedAdaBoost(1, weak="stump").fit(X, y)


# -- discrete AdaBoost, Fig. 3.3 ----------------------------------------------------------


def test_discrete_adaboost_two_rounds_by_hand() -> None:
    # x = 1..4, y = 1, 0, 1, 1: l = 3 positives, m = 1 negative → D1 = 1/6, 1/2, 1/6, 1/6.
    # Round 1: "x > 2.5" errs only on x=1: ε1 = 1/6, β1 = 1/5; correct weights × 1/5 →
    #   D2 ∝ 1/6, 1/10, 1/30, 1/30 = 1/2, 3/10, 1/10, 1/10.
    # Round 2: "x < 1.5" errs on x=3, 4: ε2 = 1/5, β2 = 1/4.
    # H(x) = 1 iff ln5·h1 + ln4·h2 ≥ ½ ln 20: x=1 → ln4 < ½ ln20 → 0 (wrong), x=2 → 0, x=3,4 → 1.
    X = np.array([[1.0], [2.0], [3.0], [4.0]])
    y = np.array([1, 0, 1, 1])
    m = DiscreteAdaBoost(2).fit(X, y)
    assert m.n_rounds_ == 2 and m.stop_reason_ == "n_rounds"
    np.testing.assert_allclose(m.weak_threshold_, [2.5, 1.5])
    assert m.weak_polarity_.tolist() == [-1, 1]
    np.testing.assert_allclose(m.weak_error_, [1 / 6, 1 / 5])
    np.testing.assert_allclose(m.beta_, [1 / 5, 1 / 4])
    np.testing.assert_allclose(m.alpha_, [math.log(5), math.log(4)])
    half = 0.5 * math.log(20)
    np.testing.assert_allclose(
        m.decision_function(X), [math.log(4) - half, -half, math.log(5) - half, math.log(5) - half]
    )
    assert m.predict(X).tolist() == [False, False, True, True]
    assert m.train_error_ == 0.25
    # the generalized booster finds the same learners with α = ½ ln((1+r)/(1−r)) (eq. 2.4)
    g = GeneralizedAdaBoost(2).fit(X, y)
    r = 1 - 2 * np.array([1 / 6, 1 / 5])
    np.testing.assert_allclose(g.weak_r_, r)
    np.testing.assert_allclose(g.alpha_, 0.5 * np.log((1 + r) / (1 - r)))
    np.testing.assert_allclose(g.decision_function(X), m.decision_function(X))


def noisy_problem(seed: int, n: int = 600, f: int = 8) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, f))
    y = X[:, 0] + X[:, 1] ** 2 - 1 + 0.7 * rng.normal(size=n) > 0
    return X, y


def test_training_error_bound_eq_2_3() -> None:
    X, y = noisy_problem(1)
    T = 30
    m = DiscreteAdaBoost(T).fit(X, y)
    D1 = np.where(y, 1 / (2 * y.sum()), 1 / (2 * (~y).sum()))
    error = float(D1[m.predict(X) != y].sum())  # weighted by the initial distribution
    eps = m.weak_error_
    bound = 2**m.n_rounds_ * np.prod(np.sqrt(eps * (1 - eps)))
    gamma = 0.5 - eps
    assert error <= bound <= math.exp(-2 * np.sum(gamma**2))
    assert bound < 1


def test_separable_data_reach_zero_training_error() -> None:
    rng = np.random.default_rng(2)
    X = rng.uniform(size=(300, 3))
    one_cut = DiscreteAdaBoost(50).fit(X, X[:, 2] > 0.3)
    assert one_cut.stop_reason_ == "perfect" and one_cut.n_rounds_ == 1 and one_cut.train_error_ == 0
    assert np.isfinite(one_cut.alpha_).all()
    both = (X[:, 0] > 0.3) & (X[:, 1] < 0.6)
    m = GeneralizedAdaBoost(100).fit(X, both)
    assert m.train_error_ == 0.0
    assert (m.predict(X) == both).all()


def test_staged_predictions_end_at_the_final_ones() -> None:
    X, y = noisy_problem(5)
    m = GeneralizedAdaBoost(20).fit(X, y)
    stages = list(m.staged_decision_function(X))
    assert len(stages) == m.n_rounds_ == 20
    np.testing.assert_allclose(stages[-1], m.decision_function(X))
    np.testing.assert_allclose(np.abs(stages[0]), m.alpha_[0])  # F_1 = α_1 h_1(x), h = ±1
    preds = list(m.staged_predict(X))
    assert (preds[-1] == m.predict(X)).all()
    errors = [np.mean(p != y) for p in preds]
    assert errors[-1] == pytest.approx(m.train_error_)
    assert errors[-1] < errors[0]


def test_confidence_eq_4_2_to_4_4() -> None:
    X, y = noisy_problem(6)
    m = GeneralizedAdaBoost(15).fit(X, y)
    F = m.decision_function(X)
    P = m.predict_proba(X)
    assert P.shape == (X.shape[0], 2)
    assert ((P >= 0) & (P <= 1)).all()
    np.testing.assert_allclose(P.sum(axis=1), 1.0)
    np.testing.assert_allclose(P[:, 1], np.exp(F) / (np.exp(-F) + np.exp(F)))
    assert ((P[:, 1] > 0.5) == (F > 0)).all()
    assert ((P[:, 1] >= 0.5) == m.predict(X)).all()
    # extreme outputs stay finite and in range
    huge = GeneralizedAdaBoost(1).fit(X, X[:, 0] > 0).predict_proba(X)
    assert np.isfinite(huge).all() and ((huge >= 0) & (huge <= 1)).all()


def test_discrete_and_generalized_pick_the_same_learners() -> None:
    X, y = noisy_problem(8)
    d = DiscreteAdaBoost(25).fit(X, y)
    g = GeneralizedAdaBoost(25).fit(X, y)
    assert (d.weak_feature_ == g.weak_feature_).all()
    np.testing.assert_allclose(d.weak_threshold_, g.weak_threshold_)
    np.testing.assert_allclose(d.alpha_, 2 * g.alpha_)
    np.testing.assert_allclose(d.decision_function(X), g.decision_function(X), atol=1e-9)


def test_initial_weights_and_sample_weight() -> None:
    X, y = noisy_problem(9, n=300)
    # balanced: duplicating every negative changes nothing (each class starts with ½)
    Xd = np.vstack([X, X[~y]])
    yd = np.concatenate([y, y[~y]])
    a = GeneralizedAdaBoost(5).fit(X, y)
    b = GeneralizedAdaBoost(5).fit(Xd, yd)
    np.testing.assert_allclose(a.alpha_, b.alpha_)
    # a sample weight of 2 is the same as a duplicate, in both modes
    for balanced in (True, False):
        c = GeneralizedAdaBoost(5, balanced=balanced).fit(Xd, yd)
        w = np.concatenate([np.ones(len(y)), np.zeros((~y).sum())])
        w[: len(y)][~y] = 2.0
        e = GeneralizedAdaBoost(5, balanced=balanced).fit(Xd, yd, sample_weight=w)
        np.testing.assert_allclose(c.alpha_, e.alpha_)
        assert (c.weak_feature_ == e.weak_feature_).all()
    with pytest.raises(ValueError, match="sample_weight"):
        GeneralizedAdaBoost(5).fit(X, y, sample_weight=-np.ones(len(y)))


def test_shared_presort_gives_the_same_model() -> None:
    X, y = noisy_problem(10)
    sf = SortedFeatures(X)
    a = GeneralizedAdaBoost(10).fit(X, y, presorted=sf)
    b = GeneralizedAdaBoost(10).fit(X, y)
    np.testing.assert_array_equal(a.decision_function(X), b.decision_function(X))
    with pytest.raises(ValueError, match="presorted"):
        GeneralizedAdaBoost(10).fit(X[:-1], y[:-1], presorted=sf)


def test_used_features_and_importance() -> None:
    X, y = noisy_problem(12, f=10)
    m = GeneralizedAdaBoost(12).fit(X, y)
    used = m.used_features()
    assert used.tolist() == sorted(set(m.weak_feature_.tolist()))
    imp = m.feature_importance()
    assert imp.shape == (10,)
    for f in range(10):
        assert imp[f] == pytest.approx(m.alpha_[m.weak_feature_ == f].sum())
    assert set(np.flatnonzero(imp).tolist()) == set(used.tolist())
    assert np.argmax(imp) in (0, 1)  # the informative columns


def test_state_round_trip_and_reindexing() -> None:
    X, y = noisy_problem(13, f=6)
    m = GeneralizedAdaBoost(10, weak="both").fit(X, y)
    meta, arrays = m.get_state()
    again = booster_from_state(meta, arrays)
    np.testing.assert_array_equal(again.decision_function(X), m.decision_function(X))
    assert again.train_error_ == m.train_error_
    used = m.used_features()
    small = m.reindexed(used)
    assert small.n_features_in_ == used.size
    np.testing.assert_array_equal(small.decision_function(X[:, used]), m.decision_function(X))
    with pytest.raises(ValueError, match="not kept"):
        m.reindexed(used[1:])
    bad = dict(arrays, alpha=arrays["alpha"][:-1])
    with pytest.raises(ValueError, match="shape"):
        booster_from_state(meta, bad)


# -- estimator manners ------------------------------------------------------------------


def test_init_only_stores_parameters() -> None:
    m = GeneralizedAdaBoost(7, weak="interval", balanced=False)
    assert m.get_params() == {"n_rounds": 7, "weak": "interval", "balanced": False}
    assert not hasattr(m, "alpha_")
    X, y = noisy_problem(14, n=100)
    assert m.fit(X, y) is m
    assert "GeneralizedAdaBoost(n_rounds=7" in repr(m)


@pytest.mark.parametrize("cls", [DiscreteAdaBoost, GeneralizedAdaBoost])
def test_unfitted_booster_raises(cls: type) -> None:
    m = cls()
    X = np.zeros((3, 2))
    for call in (m.predict, m.decision_function, m.predict_proba):
        with pytest.raises(NotFittedError, match="not fitted"):
            call(X)
    with pytest.raises(NotFittedError):
        m.used_features()
    with pytest.raises(NotFittedError):
        list(m.staged_predict(X))


@pytest.mark.parametrize(
    ("y", "message"),
    [
        (np.array([0, 1, 2, 1]), "binary"),
        (np.array(["a", "b", "a", "b"]), "bool"),
        (np.array([1, 1, 1, 1]), "one class"),
        (np.array([True, False, True]), "shape"),
        (np.array([0.5, 1, 0, 1]), "binary"),
    ],
)
def test_bad_labels_raise_value_error(y: np.ndarray, message: str) -> None:
    X = np.arange(8.0).reshape(4, 2)
    with pytest.raises(ValueError, match=message):
        GeneralizedAdaBoost(3).fit(X, y)


def test_accepts_every_binary_label_encoding() -> None:
    X, y = noisy_problem(15, n=200)
    ref = GeneralizedAdaBoost(5).fit(X, y).decision_function(X)
    for labels in (y.astype(int), np.where(y, 1, -1), y.astype(float)):
        np.testing.assert_array_equal(GeneralizedAdaBoost(5).fit(X, labels).decision_function(X), ref)


def test_bad_features_raise_value_error() -> None:
    X, y = noisy_problem(16, n=50)
    Xn = X.copy()
    Xn[3, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        GeneralizedAdaBoost(3).fit(Xn, y)
    with pytest.raises(ValueError, match="2-D"):
        GeneralizedAdaBoost(3).fit(X[:, 0], y)
    m = GeneralizedAdaBoost(3).fit(X, y)
    with pytest.raises(ValueError, match="features"):
        m.predict(X[:, :3])
    with pytest.raises(ValueError, match="n_rounds"):
        GeneralizedAdaBoost(0).fit(X, y)
    with pytest.raises(ValueError, match="better than chance"):
        GeneralizedAdaBoost(3).fit(np.ones((50, 2)), y)
