"""The decision threshold on ``F`` chosen from the TRAINING split only, by cross-validation.

The book decides at the sign of the strong classifier (``F ≥ 0``). The issue's targets bound
the false-negative and the false-positive rate separately, so a detector may instead be given
the threshold that makes the larger of the two smallest — estimated on scores the detector did
not train on, and never on the test split:

1. :func:`cv_folds` cuts the training examples into groups that do not share a recording
   stretch: one positive file per fold (files are assigned round-robin), and each negative
   file cut into ``n_folds`` contiguous blocks of scans (consecutive scans of the same chair
   never fall on both sides).
2. :func:`out_of_fold_scores`: for every fold, a detector with the same parameters is trained
   on the other folds and scores this one.
3. :func:`balanced_threshold`: the threshold on those scores that minimises
   ``max(FN rate, FP rate)`` (ties: the one nearest 0, the book's).

Everything here is a pure function of arrays (no files).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from knowledge.people.dataset import Examples
from knowledge.people.detector import LegDetector
from knowledge.people.segmentation import FloatArray

#: Folds of the training split (four positive files in the issue's protocol).
DEFAULT_FOLDS = 4


def cv_folds(examples: Examples, n_folds: int = DEFAULT_FOLDS) -> npt.NDArray[np.intp]:
    """``(n,)`` fold index in ``[0, n_folds)`` of every example (see the module doc).

    Parts with a positive example are whole folds (round-robin over those parts); the other
    parts are cut into ``n_folds`` blocks of consecutive scans, block ``k`` in fold ``k``.
    """
    if int(n_folds) != n_folds or n_folds < 2:
        raise ValueError(f"n_folds must be an integer >= 2, got {n_folds!r}")
    folds = np.zeros(examples.y.shape[0], dtype=np.intp)
    positive_parts = [pi for pi in range(len(examples.parts)) if examples.y[examples.part == pi].any()]
    for k, pi in enumerate(positive_parts):
        folds[examples.part == pi] = k % n_folds
    for pi in range(len(examples.parts)):
        if pi in positive_parts:
            continue
        m = examples.part == pi
        if not m.any():
            continue
        s = examples.scan[m]
        lo, hi = int(s.min()), int(s.max()) + 1
        folds[m] = np.minimum((s - lo) * n_folds // (hi - lo), n_folds - 1)
    return folds


def out_of_fold_scores(
    make: Callable[[], LegDetector], X: npt.ArrayLike, y: npt.ArrayLike, folds: npt.ArrayLike
) -> FloatArray:
    """``(n,)`` ``F`` of every example from a detector (``make()``) trained without its fold.

    ``X`` ``(n, 14)`` features, ``y`` ``(n,)`` bool labels, ``folds`` ``(n,)`` fold indices.
    Raises ValueError when a fold leaves the others without one of the classes.
    """
    A = np.asarray(X, dtype=np.float64)
    t = np.asarray(y, dtype=bool)
    f = np.asarray(folds)
    if A.shape[0] != t.shape[0] or f.shape != t.shape:
        raise ValueError(f"X {A.shape}, y {t.shape} and folds {f.shape} must have the same length")
    out = np.empty(t.shape[0])
    for k in np.unique(f).tolist():
        held = f == k
        rest = t[~held]
        if rest.all() or not rest.any():
            raise ValueError(
                f"without fold {k} the training examples hold only one class: use fewer folds or more data"
            )
        out[held] = make().fit(A[~held], rest).decision_function(A[held])
    return out


@dataclass(frozen=True)
class ThresholdChoice:
    """A threshold on ``F`` and the rates it gives on the scores it was chosen on (percent)."""

    threshold: float
    false_negative_rate_pct: float
    false_positive_rate_pct: float


def balanced_threshold(
    score: npt.ArrayLike, y: npt.ArrayLike, classified: npt.ArrayLike | None = None
) -> ThresholdChoice:
    """The threshold ``θ`` (person iff ``F ≥ θ``) minimising ``max(FN %, FP %)`` on these scores.

    ``score`` ``(n,)`` F, ``y`` ``(n,)`` bool truth, ``classified`` ``(n,)`` bool: examples the
    detector classifies at all (the others are non-persons whatever their score; default all).
    Candidates are the midpoints between consecutive distinct scores and the ends; among equally
    good ones the one nearest 0 is taken.
    """
    F = np.asarray(score, dtype=np.float64)
    t = np.asarray(y, dtype=bool)
    ok = np.ones(t.shape, dtype=bool) if classified is None else np.asarray(classified, dtype=bool)
    if F.shape != t.shape or ok.shape != t.shape or F.ndim != 1:
        raise ValueError(f"score {F.shape}, y {t.shape} and classified {ok.shape} must be equal 1-D shapes")
    if t.all() or not t.any():
        raise ValueError("y needs people and non-people to choose a threshold")
    u = np.unique(F[ok]) if ok.any() else np.zeros(1)
    cand = np.concatenate(([u[0] - 1.0], 0.5 * (u[1:] + u[:-1]), [u[-1] + 1.0], [0.0]))
    # counts of positives / negatives with F >= θ among the classified ones, by sorting
    pos = np.sort(F[ok & t])
    neg = np.sort(F[ok & ~t])
    n_pos, n_neg = int(t.sum()), int((~t).sum())
    fn = 100.0 * (n_pos - (pos.size - np.searchsorted(pos, cand, side="left"))) / n_pos
    fp = 100.0 * (neg.size - np.searchsorted(neg, cand, side="left")) / n_neg
    worst = np.maximum(fn, fp)
    best = np.flatnonzero(worst <= worst.min() + 1e-12)
    i = int(best[np.argmin(np.abs(cand[best]))])
    return ThresholdChoice(float(cand[i]), float(fn[i]), float(fp[i]))
