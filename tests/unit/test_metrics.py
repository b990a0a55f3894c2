"""Accuracy, balanced accuracy and confusion matrices on hand-counted cases."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.learning.metrics import format_confusion, score


def test_scores_by_hand() -> None:
    yt = np.array(["room"] * 6 + ["corridor"] * 3 + ["doorway"])
    yp = np.array(["room"] * 5 + ["corridor"] + ["corridor"] * 2 + ["room"] + ["room"])
    s = score(yt, yp, ["room", "corridor", "doorway"])
    assert s.n == 10
    assert s.accuracy == pytest.approx(7 / 10)
    assert s.confusion.tolist() == [[5, 1, 0], [1, 2, 0], [1, 0, 0]]
    assert s.balanced_accuracy == pytest.approx((5 / 6 + 2 / 3 + 0) / 3)
    assert s.precision[0] == pytest.approx(5 / 7)
    assert np.isnan(s.precision[2])
    assert "recall" in format_confusion(s)


def test_classes_outside_the_list_are_ignored_in_truth_and_wrong_in_prediction() -> None:
    yt = np.array(["room", "corridor", "doorway", "room"])
    yp = np.array(["room", "corridor", "room", "doorway"])
    s = score(yt, yp, ["room", "corridor"])
    assert s.n == 3  # the doorway cell is not scored
    assert s.accuracy == pytest.approx(2 / 3)  # a room predicted as doorway is wrong
    d = s.as_dict()
    assert d["recall"] == {"room": 0.5, "corridor": 1.0}


def test_shape_mismatch() -> None:
    with pytest.raises(ValueError, match="differ in shape"):
        score(np.array(["a"]), np.array(["a", "b"]), ["a"])
