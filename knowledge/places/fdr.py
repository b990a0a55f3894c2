"""Scalar feature selection by Fisher's discrimination ratio with a correlation penalty (Sect. 4.6.3).

A *filter* (it involves no classifier): every column of a feature matrix is scored on its
own by the multi-class FDR (eq. 4.12), then features are picked greedily, each one trading
its FDR against its mean absolute correlation with those already picked (eq. 4.13, Fig. 4.6).
Usable for any of the project's learners; :mod:`knowledge.places.iamn` uses it to cut the
scan features down to the ≤ 30 that the nearest-neighbour transform reads.

Settled where the printed text is ambiguous:

* eq. 4.12: σ_i is the *variance* of class i (docs/BOOK.md); the double sum counts each pair
  of classes twice, as printed. A feature constant on the training data scores 0; a
  denominator of 0 with different means (two classes each constant) is floored at 1e-12 of
  the feature's overall variance, so such a feature scores high but finite.
* eq. 4.13 prints the correlation of the raw values. Scan features are mostly positive
  lengths and areas, whose raw cross-correlation is close to 1 for almost every pair, so
  the penalty would hardly tell a duplicate from an unrelated feature. We apply eq. 4.13 to
  the mean-centred values (Pearson's coefficient), as the source the book cites
  (Theodoridis & Koutroumbas) does after normalising the features.
* Fig. 4.6 weighs S(f) against |ρ| with w_1 and w_2 but gives no values. FDR values span
  orders of magnitude, so S is divided by its maximum (the first pick's score is 1) before
  the weighing; the defaults are w_1 = w_2 = 1. The sum in the third step runs over the
  l* − 1 features already picked (the printed upper limit l* includes the candidate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def fisher_ratios(X: npt.ArrayLike, y: npt.ArrayLike) -> FloatArray:
    """Multi-class FDR (eq. 4.12) of every column of ``X``.

    Args:
        X: ``(N, F)`` feature values.
        y: ``(N,)`` class labels (any hashable values); at least two classes.

    Returns:
        ``(F,)`` float64 scores, ≥ 0; larger separates the classes better.
    """
    A = np.asarray(X, dtype=np.float64)
    labels = np.asarray(y)
    if A.ndim != 2 or labels.shape != (A.shape[0],):
        raise ValueError(f"X must be (N, F) and y (N,), got {A.shape} and {labels.shape}")
    classes = np.unique(labels)
    if len(classes) < 2:
        raise ValueError(f"FDR needs at least two classes, got {classes.tolist()}")
    if not np.all(np.isfinite(A)):
        raise ValueError("X holds NaN or infinite values; clean the features first")
    mu = np.stack([A[labels == c].mean(axis=0) for c in classes])  # (K, F)
    var = np.stack([A[labels == c].var(axis=0) for c in classes])  # (K, F)
    floor = 1e-12 * A.var(axis=0)
    constant = A.var(axis=0) == 0.0
    score = np.zeros(A.shape[1])
    for i in range(len(classes)):
        for j in range(len(classes)):
            if i == j:
                continue
            den = np.maximum(var[i] + var[j], floor)
            with np.errstate(divide="ignore", invalid="ignore"):
                score += np.where(constant, 0.0, (mu[i] - mu[j]) ** 2 / den)
    return score


def correlations(X: npt.ArrayLike) -> FloatArray:
    """``(F, F)`` cross-correlation coefficients (eq. 4.13) of the mean-centred columns of ``X``.

    A constant column correlates 0 with every other column (and 1 with itself).
    """
    A = np.asarray(X, dtype=np.float64)
    C = A - A.mean(axis=0)
    norm = np.sqrt(np.sum(C * C, axis=0))
    safe = np.where(norm > 0, norm, 1.0)
    R = (C.T @ C) / np.outer(safe, safe)
    R[norm == 0, :] = 0.0
    R[:, norm == 0] = 0.0
    np.fill_diagonal(R, 1.0)
    return np.clip(R, -1.0, 1.0)


@dataclass(frozen=True)
class Selection:
    """The features Fig. 4.6 picked, in the order picked.

    Attributes:
        indices: ``(L*,)`` column indices into the input matrix.
        fdr: ``(L*,)`` their FDR (eq. 4.12), unnormalised.
        scores: ``(L*,)`` the criterion w_1·S(f)/max S − w_2·mean |ρ| at the moment each was picked.
    """

    indices: npt.NDArray[np.intp]
    fdr: FloatArray
    scores: FloatArray


def select_features(
    X: npt.ArrayLike,
    y: npt.ArrayLike,
    n_select: int,
    *,
    w1: float = 1.0,
    w2: float = 1.0,
) -> Selection:
    """Pick ``n_select`` columns of ``X`` by the greedy FDR/correlation rule of Fig. 4.6.

    Args:
        X: ``(N, F)`` feature values of the training examples.
        y: ``(N,)`` their class labels.
        n_select: L*, how many features to keep (at most F).
        w1, w2: the weights of the normalised FDR and of the mean absolute correlation.

    Returns:
        The :class:`Selection` (indices in the order picked, never one twice).
    """
    A = np.asarray(X, dtype=np.float64)
    if n_select < 1 or n_select > A.shape[1]:
        raise ValueError(f"n_select must be in 1..{A.shape[1]} (the number of features), got {n_select}")
    if w1 < 0 or w2 < 0:
        raise ValueError(f"w1 and w2 must be ≥ 0, got {w1} and {w2}")
    fdr = fisher_ratios(A, y)
    top = float(fdr.max())
    S = fdr / top if top > 0 else fdr
    R = np.abs(correlations(A))
    picked: list[int] = []
    scores: list[float] = []
    penalty = np.zeros(A.shape[1])
    available = np.ones(A.shape[1], dtype=bool)
    for step in range(n_select):
        crit = w1 * S - (w2 * penalty / step if step else 0.0)
        crit = np.where(available, crit, -np.inf)
        f = int(np.argmax(crit))
        picked.append(f)
        scores.append(float(crit[f]))
        available[f] = False
        penalty += R[f]
    idx = np.asarray(picked, dtype=np.intp)
    return Selection(indices=idx, fdr=fdr[idx], scores=np.asarray(scores))
