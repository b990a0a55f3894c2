"""Decision lists of one-vs-all boosters (book Sect. 3.3) and the probabilistic list (4.3, eq. 4.5)."""

from __future__ import annotations

import itertools
import math
from functools import partial

import numpy as np
import pytest

from knowledge.errors import NotFittedError
from knowledge.labels import CLASS_NAMES
from knowledge.learning.boosting import GeneralizedAdaBoost
from knowledge.learning.decision_list import DecisionList, class_names, histogram, order_name

NAMES = ["room", "corridor", "doorway", "hallway"]


def blobs(n: int, k: int, seed: int, spread: float = 1.6) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Gaussian classes in 5-D: names (N,) and features (N, 5)."""
    rng = np.random.default_rng(seed)
    centers = rng.normal(scale=spread, size=(k, 5))
    label = rng.integers(0, k, size=n)
    X = centers[label] + rng.normal(size=(n, 5))
    return X, np.asarray(NAMES, dtype=str)[label]


def small_list(**kwargs: object) -> DecisionList:
    return DecisionList(partial(GeneralizedAdaBoost, n_rounds=15), **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("k", [3, 4])
def test_best_order_is_the_most_accurate_permutation(k: int) -> None:
    X, y = blobs(1200, k, seed=k)
    dl = small_list().fit(X[:700], y[:700], selection_data=(X[700:], y[700:]))
    assert dl.selection_ == "validation"
    assert len(dl.order_scores_) == math.factorial(k)
    assert {o for o, _ in dl.order_scores_} == set(itertools.permutations(dl.classes_.tolist()))
    # every order evaluated independently through the public API
    independent = {order: dl.with_order(order).score(X[700:], y[700:]) for order, _ in dl.order_scores_}
    for order, acc in dl.order_scores_:
        assert acc == pytest.approx(independent[order])
    assert dl.order_ == dl.order_scores_[0][0]
    assert independent[dl.order_] == max(independent.values())
    scores = [a for _, a in dl.order_scores_]
    assert scores == sorted(scores, reverse=True)
    # the orders really differ (otherwise the test could not fail)
    assert len(set(independent.values())) > 1


def test_histogram_rows_sum_to_one_and_follow_classes() -> None:
    X, y = blobs(900, 4, seed=1)
    dl = small_list().fit(X, y)
    assert dl.selection_ == "training"
    P = dl.predict_proba(X)
    assert P.shape == (900, 4)
    assert ((P >= 0) & (P <= 1)).all()
    np.testing.assert_allclose(P.sum(axis=1), 1.0)
    assert (dl.classes_[np.argmax(P, axis=1)] == dl.predict(X)).all()
    assert dl.score(X, y) > 0.6


def test_eq_4_5_by_hand() -> None:
    C = np.array([[0.2, 0.5], [0.9, 0.1], [0.0, 0.0]])
    P = histogram(C)
    np.testing.assert_allclose(P[0], [0.2, 0.8 * 0.5, 0.8 * 0.5])
    np.testing.assert_allclose(P[1], [0.9, 0.1 * 0.1, 0.1 * 0.9])
    np.testing.assert_allclose(P[2], [0.0, 0.0, 1.0])


def hand_list(c_first: float, c_second: float) -> tuple[DecisionList, np.ndarray]:
    """A fitted list corridor → room → doorway whose boosters answer ``c_first``, ``c_second``
    on x = 0 (one stump each, h = +1 for x < 0.5, α = atanh(2C − 1))."""

    def booster(c: float) -> dict[str, np.ndarray]:
        return {
            "weak_feature": np.array([0]),
            "weak_kind": np.array([0]),
            "weak_threshold": np.array([0.5]),
            "weak_upper": np.array([np.nan]),
            "weak_polarity": np.array([1]),
            "alpha": np.array([math.atanh(2 * c - 1)]),
            "weak_error": np.array([0.1]),
        }

    meta = {
        "classes": ["room", "corridor", "doorway"],
        "order": ["corridor", "room", "doorway"],
        "order_mode": "explicit",
        "probabilistic": True,
        "boosters": [
            {"class": "corridor", "type": "generalized", "n_features_in": 1},
            {"class": "room", "type": "generalized", "n_features_in": 1},
        ],
    }
    arrays = {f"b0.{k}": v for k, v in booster(c_first).items()}
    arrays.update({f"b1.{k}": v for k, v in booster(c_second).items()})
    return DecisionList.from_state(meta, arrays), np.zeros((1, 1))


def test_eq_4_5_through_the_list_and_the_class_order() -> None:
    dl, x = hand_list(0.3, 0.6)
    P = dl.predict_proba(x)[0]  # columns: room, corridor, doorway
    np.testing.assert_allclose(P, [0.7 * 0.6, 0.3, 0.7 * 0.4])
    assert dl.predict(x).tolist() == ["room"]
    assert order_name(dl.order_) == "corridor-room"


def test_sequential_rule_and_argmax_differ_as_documented() -> None:
    # First booster 0.49 (negative), second 0.9 (positive): sequential → room (2nd);
    # histogram = [0.49, 0.51·0.9 = 0.459, 0.051] → argmax corridor (1st).
    dl, x = hand_list(0.49, 0.9)
    assert dl.predict_sequential(x).tolist() == ["room"]
    assert dl.predict(x).tolist() == ["corridor"]
    # No booster positive: sequential → the default (doorway); argmax → corridor (0.4 > 0.36 > 0.24).
    dl, x = hand_list(0.4, 0.4)
    assert dl.predict_sequential(x).tolist() == ["doorway"]
    assert dl.predict(x).tolist() == ["corridor"]
    # First booster positive: both rules agree.
    dl, x = hand_list(0.55, 0.99)
    assert dl.predict_sequential(x).tolist() == dl.predict(x).tolist() == ["corridor"]
    # probabilistic=False makes predict sequential
    dl, x = hand_list(0.49, 0.9)
    dl.probabilistic = False
    assert dl.predict(x).tolist() == ["room"]


def test_heuristic_order_sorts_by_training_error() -> None:
    X, y = blobs(900, 4, seed=2)
    dl = small_list(order="heuristic").fit(X, y)
    errors = [dl.train_errors_[c] for c in dl.order_]
    assert errors == sorted(errors)
    assert len(dl.order_scores_) == 1 and dl.order_scores_[0][0] == dl.order_
    assert dl.order_scores_[0][1] == pytest.approx(dl.score(X, y))


def test_explicit_order_is_used_as_given() -> None:
    X, y = blobs(600, 3, seed=3)
    order = ("doorway", "room", "corridor")
    dl = small_list(order=order).fit(X, y)
    assert dl.order_ == order
    assert dl.order_mode == "explicit"
    with pytest.raises(ValueError, match="every class"):
        small_list(order=("doorway", "room")).fit(X, y)
    with pytest.raises(ValueError, match="heuristic"):
        small_list(order="fastest").fit(X, y)


def test_used_features_skip_the_default_class() -> None:
    rng = np.random.default_rng(4)
    n = 600
    label = rng.integers(0, 3, size=n)
    X = rng.normal(size=(n, 6))
    X[:, 0] += 3 * (label == 0)  # room
    X[:, 1] += 3 * (label == 1)  # corridor
    X[:, 2] += 3 * (label == 2)  # doorway
    y = np.asarray(["room", "corridor", "doorway"])[label]
    dl = DecisionList(partial(GeneralizedAdaBoost, n_rounds=1), order=("room", "corridor", "doorway")).fit(
        X, y
    )
    assert dl.used_features().tolist() == [0, 1]
    assert set(dl.boosters_["doorway"].used_features().tolist()) == {2}


def test_labels_as_codes_and_names() -> None:
    X, y = blobs(600, 3, seed=5)
    codes = np.array([NAMES.index(c) for c in y])
    by_index = small_list().fit(X, codes, classes=NAMES)
    by_name = small_list().fit(X, y, classes=NAMES)
    assert by_index.classes_.tolist() == ["room", "corridor", "doorway"]  # order of classes=, hallway absent
    np.testing.assert_array_equal(by_index.predict_proba(X), by_name.predict_proba(X))
    label_codes = np.array([{v: k for k, v in CLASS_NAMES.items()}[c] for c in y])
    by_code = small_list().fit(X, label_codes, classes=CLASS_NAMES)
    np.testing.assert_array_equal(by_code.predict_proba(X), by_name.predict_proba(X))
    assert sorted(small_list().fit(X, y).classes_.tolist()) == ["corridor", "doorway", "room"]
    with pytest.raises(ValueError, match="classes="):
        small_list().fit(X, codes)
    with pytest.raises(ValueError, match="not among"):
        class_names(np.array(["room", "kitchen"]), ["room", "corridor"])
    with pytest.raises(ValueError, match="mapping"):
        class_names(np.array([1, 9]), CLASS_NAMES)
    with pytest.raises(ValueError, match="two classes"):
        small_list().fit(X, np.full(len(y), "room"))


def test_unfitted_list_raises() -> None:
    dl = small_list()
    with pytest.raises(NotFittedError, match="not fitted"):
        dl.predict(np.zeros((2, 5)))
    with pytest.raises(NotFittedError):
        dl.predict_proba(np.zeros((2, 5)))
    with pytest.raises(NotFittedError):
        dl.used_features()


def test_state_round_trip() -> None:
    X, y = blobs(600, 4, seed=6)
    dl = small_list().fit(X, y)
    meta, arrays = dl.get_state()
    again = DecisionList.from_state(meta, arrays)
    np.testing.assert_array_equal(again.predict_proba(X), dl.predict_proba(X))
    assert again.order_ == dl.order_ and again.classes_.tolist() == dl.classes_.tolist()
    assert len(again.order_scores_) == 24
    # every booster is kept, so the list can be reordered and all orders scored
    rev = again.with_order(tuple(reversed(dl.order_)))
    assert rev.order_ == tuple(reversed(dl.order_))
    table = again.order_accuracies(X, y)
    assert len(table) == 24
    assert dict(table)[dl.order_] == pytest.approx(dl.score(X, y))
    assert [a for _, a in table] == sorted((a for _, a in table), reverse=True)
    # a list saved without the default class's booster can't be reordered
    meta["boosters"] = meta["boosters"][:-1]
    partial = DecisionList.from_state(meta, arrays)
    with pytest.raises(ValueError, match="no booster"):
        partial.with_order(tuple(reversed(dl.order_)))
