"""The training-only decision threshold: folds, out-of-fold scores, the balanced threshold."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.people.dataset import Examples, Part
from knowledge.people.detector import LegDetector
from knowledge.people.threshold import balanced_threshold, cv_folds, out_of_fold_scores


def rates(score: np.ndarray, y: np.ndarray, theta: float, ok: np.ndarray) -> tuple[float, float]:
    p = (score >= theta) & ok
    return 100.0 * float((~p[y]).mean()), 100.0 * float(p[~y].mean())


def test_balanced_threshold_is_the_best_by_brute_force() -> None:
    rng = np.random.default_rng(3)
    y = rng.random(400) < 0.2
    F = np.where(y, rng.normal(2.0, 1.0, 400), rng.normal(-1.0, 1.0, 400))
    ok = rng.random(400) < 0.9
    c = balanced_threshold(F, y, ok)
    fn, fp = rates(F, y, c.threshold, ok)
    assert (fn, fp) == pytest.approx((c.false_negative_rate_pct, c.false_positive_rate_pct))
    best = min(max(rates(F, y, float(t), ok)) for t in np.concatenate([F, [F.min() - 1, F.max() + 1]]))
    assert max(fn, fp) == pytest.approx(best)
    # the classes are centred at +2 and -1: the balanced point lies between them, not at 0
    assert -1.0 < c.threshold < 2.0 and c.threshold > 0.0


def test_balanced_threshold_prefers_zero_and_checks_input() -> None:
    y = np.array([True, True, False, False])
    F = np.array([3.0, 2.0, -2.0, -3.0])  # separable: every θ in (-2, 2] is perfect
    c = balanced_threshold(F, y)
    assert c.threshold == 0.0 and c.false_negative_rate_pct == c.false_positive_rate_pct == 0.0
    with pytest.raises(ValueError, match="people and non-people"):
        balanced_threshold(F, np.ones(4, dtype=bool))
    with pytest.raises(ValueError, match="1-D"):
        balanced_threshold(F, y[:3])


def examples(n_per_part: int = 60, seed: int = 0) -> Examples:
    """Two positive files (people + a few in-arc non-people) and one negative file."""
    rng = np.random.default_rng(seed)
    parts = (Part("positive_1"), Part("positive_2"), Part("negative_2.left", 10, 50))
    ys, part, scan = [], [], []
    for pi in range(3):
        y = rng.random(n_per_part) < (0.7 if pi < 2 else 0.0)
        ys.append(y)
        part.append(np.full(n_per_part, pi))
        lo = parts[pi].first
        scan.append(np.sort(rng.integers(lo, lo + 40, n_per_part)))
    y = np.concatenate(ys)
    X = rng.normal(0.0, 1.0, (y.size, 14))
    X[:, 0] = rng.integers(2, 30, y.size)
    X[:, 8] += np.where(y, 1.5, 0.0)  # C.9 separates the classes, with overlap
    return Examples(
        X=X,
        y=y,
        part=np.concatenate(part),
        scan=np.concatenate(scan),
        segment=np.zeros(y.size, dtype=np.intp),
        distance=rng.uniform(0.5, 6.0, y.size),
        parts=parts,
        diagnostics={},
    )


def test_cv_folds_keep_files_and_time_blocks_apart() -> None:
    ex = examples()
    f = cv_folds(ex, 2)
    assert set(np.unique(f[ex.part == 0]).tolist()) == {0}
    assert set(np.unique(f[ex.part == 1]).tolist()) == {1}
    neg = ex.part == 2
    s, fn = ex.scan[neg], f[neg]
    assert set(fn.tolist()) == {0, 1}
    assert s[fn == 0].max() < s[fn == 1].min()  # contiguous blocks of scans
    for k in (0, 1):  # every fold leaves both classes for training
        assert ex.y[f != k].any() and (~ex.y[f != k]).any()
    with pytest.raises(ValueError, match="n_folds"):
        cv_folds(ex, 1)


def test_out_of_fold_scores_come_from_detectors_without_the_fold() -> None:
    ex = examples()
    f = cv_folds(ex, 2)

    def make() -> LegDetector:
        return LegDetector(n_rounds=10, columns=(0, 8))

    F = out_of_fold_scores(make, ex.X, ex.y, f)
    held = f == 1
    direct = make().fit(ex.X[~held], ex.y[~held]).decision_function(ex.X[held])
    np.testing.assert_allclose(F[held], direct)
    full = make().fit(ex.X, ex.y).decision_function(ex.X)
    assert not np.allclose(F, full)  # not the scores of the detector trained on everything
    # C.9 carries the signal: held-out scores still rank people above non-people
    assert F[ex.y].mean() > F[~ex.y].mean()
    only_people = np.where(ex.y, 0, 1)
    with pytest.raises(ValueError, match="one class"):
        out_of_fold_scores(make, ex.X, ex.y, only_people)
