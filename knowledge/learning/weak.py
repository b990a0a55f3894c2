"""Weak learners for boosting: threshold stumps (book eq. 3.1/4.1) and intervals (eq. 5.2).

A weak learner looks at one feature ``f`` (one column of the ``(N, F)`` feature matrix) and
answers ±1:

* threshold (eq. 4.1): ``h(x) = +1 if p·f(x) < p·θ else −1``, with polarity ``p ∈ {−1, +1}``;
* interval (eq. 5.2): ``h(x) = p if θ¹ < f(x) < θ² else −p``; θ¹ may be −∞ and θ² +∞, so an
  interval learner also finds every threshold (the whole line, a constant, is excluded).

The discrete AdaBoost of Fig. 3.3 uses the same learners with outputs ``{0, 1}`` = ``(h + 1)/2``.

:class:`SortedFeatures` finds the learner that maximises ``r = Σ_n D(n) y_n h(x_n)`` (eq. 2.5),
which is the same as minimising the weighted error ``ε = Σ D |h − y|`` of eq. 3.2 for ±1/0-1
outputs (``ε = (1 − r)/2``), exactly, over every feature. It sorts every feature once; each
round it sums the signed weights ``D·y`` cumulatively in the order of each feature and reads
every split from those prefix sums: O(F·N) per round, vectorised over features in chunks.
Splits only fall between distinct values (never inside a run of ties), thresholds sit at the
midpoint between the two neighbouring distinct values, and both polarities are considered.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

KIND_THRESHOLD = 0
KIND_INTERVAL = 1
KIND_NAMES = {KIND_THRESHOLD: "threshold", KIND_INTERVAL: "interval"}

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

#: Elements (features × examples) gathered at once in a round; small enough to stay in cache.
ROUND_CHUNK_ELEMENTS = 1 << 16
#: Elements sorted at once when building :class:`SortedFeatures` (bounds the temporaries).
SORT_CHUNK_ELEMENTS = 1 << 21


def as_feature_matrix(X: npt.ArrayLike, *, what: str = "X") -> npt.NDArray[np.floating]:
    """Validate a feature matrix: 2-D ``(N, F)``, real, finite. float32/float64 are kept as is."""
    A = np.asarray(X)
    if A.ndim != 2:
        raise ValueError(f"{what} must be a 2-D (examples, features) array, got shape {A.shape}")
    if A.dtype.kind not in "fiub":
        raise ValueError(f"{what} must hold numbers, got dtype {A.dtype}")
    if A.dtype not in (np.float32, np.float64):
        A = A.astype(np.float64)
    rows = max(1, (1 << 20) // max(1, A.shape[1]))
    for r0 in range(0, A.shape[0], rows):  # in blocks: no N×F temporary
        finite = np.isfinite(A[r0 : r0 + rows])
        if finite.all():
            continue
        bad = np.argwhere(~finite)[0] + (r0, 0)
        raise ValueError(
            f"{what} has a non-finite value (NaN or inf) at row {bad[0]}, column {bad[1]}: "
            "features must be finite; replace them (e.g. by the sensor's maximum range) first"
        )
    return A


@dataclass(frozen=True)
class WeakLearner:
    """One learner found by :meth:`SortedFeatures.best`.

    ``threshold`` is θ of a threshold learner or θ¹ of an interval (may be −inf); ``upper`` is
    θ² of an interval (may be +inf) and NaN for a threshold. ``r = Σ D y h`` is recomputed
    exactly from the learner's outputs on the training examples (weights summing to 1 give
    the weighted error ``(1 − r)/2``).
    """

    feature: int
    kind: int
    threshold: float
    upper: float
    polarity: int
    r: float

    def predict(self, values: npt.ArrayLike) -> npt.NDArray[np.int8]:
        """±1 outputs for the values of this learner's feature, shape ``(N,)``."""
        lo, hi, s = inside_form(
            np.array([self.kind]),
            np.array([self.threshold]),
            np.array([self.upper]),
            np.array([self.polarity]),
        )
        v = np.asarray(values, dtype=np.float64)
        inside = (v > lo[0]) & (v < hi[0])
        return np.where(inside, np.int8(s[0]), np.int8(-s[0]))


def inside_form(
    kind: npt.NDArray[np.integer],
    threshold: FloatArray,
    upper: FloatArray,
    polarity: npt.NDArray[np.integer],
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int8]]:
    """Every learner as ``h = s if lo < f < hi else −s``: returns ``(lo, hi, s)``, each ``(T,)``.

    Threshold ``p = +1`` (``f < θ``) is ``(−inf, θ)`` with ``s = +1``; ``p = −1`` (``f > θ``) is
    ``(θ, +inf)`` with ``s = +1``; an interval is ``(θ¹, θ²)`` with ``s = p``.
    """
    is_int = np.asarray(kind) == KIND_INTERVAL
    p = np.asarray(polarity)
    th = np.asarray(threshold, dtype=np.float64)
    lo = np.where(is_int, th, np.where(p > 0, -np.inf, th))
    hi = np.where(is_int, np.asarray(upper, dtype=np.float64), np.where(p > 0, th, np.inf))
    s = np.where(is_int, p, 1).astype(np.int8)
    return lo, hi, s


def _permute_rows(a: npt.NDArray[Any], perm: npt.NDArray[np.intp]) -> None:
    """Reorder the rows of ``a`` in place so that new row k is old row ``perm[k]`` (one spare row)."""
    done = np.zeros(len(perm), dtype=bool)
    spare = np.empty_like(a[0]) if len(perm) else a[:0]
    for start in range(len(perm)):
        if done[start]:
            continue
        spare[...] = a[start]
        k = start
        while True:
            done[k] = True
            src = int(perm[k])
            if src == start:
                a[k] = spare
                break
            a[k] = a[src]
            k = src


def _between(a: float, b: float, fallback: float) -> float:
    """The midpoint of ``a < b``, or ``fallback`` when a and b are adjacent doubles."""
    mid = 0.5 * a + 0.5 * b
    return mid if a < mid < b else fallback


class SortedFeatures:
    """The columns of a feature matrix sorted once, for exact weak-learner search each round.

    A feature with many distinct values ("fine") keeps its argsort; each round the signed
    weights are gathered in sorted order and summed cumulatively. A feature with few
    distinct values ("coarse": at most N/8, e.g. counts) keeps the rank of each example's
    value among the distinct values; each round ``np.bincount`` sums the weights per value,
    which is several times cheaper than a gather and a cumulative sum over N.

    Memory: 4 bytes per example and feature (int32 order or rank; 360 MB for 300 features ×
    300 000 examples), one more byte per example for each fine feature that has tied
    values, and the distinct values of the coarse features. ``X`` is kept by reference.
    Several boosters trained on the same ``X`` (the one-vs-all classifiers of a decision
    list) can share one instance.
    """

    def __init__(self, X: npt.ArrayLike) -> None:
        A = as_feature_matrix(X)
        N, F = A.shape
        if N < 2:
            raise ValueError(f"need at least 2 examples to learn a split, got {N}")
        self.X = A
        self.n_samples = N
        self.n_features = F
        index_type = np.int32 if N < 2**31 else np.int64
        # Row f holds the argsort (fine) or the ranks (coarse) of feature f; reordered at the
        # end to all fine rows, then all coarse rows, without a second copy.
        index = np.empty((F, N), dtype=index_type)
        tie_masks: list[npt.NDArray[np.bool_]] = []
        uniques: list[FloatArray] = []
        #: For each feature: True if coarse (ranks), False if fine (order).
        self.coarse = np.zeros(F, dtype=bool)
        #: Row of ``valid`` for a fine feature with ties, −1 otherwise.
        self.valid_row = np.full(F, -1, dtype=np.intp)
        step = max(1, SORT_CHUNK_ELEMENTS // N)
        for c0 in range(0, F, step):
            c1 = min(F, c0 + step)
            block = np.ascontiguousarray(A[:, c0:c1].T)
            idx = np.argsort(block, axis=1)
            xs = np.take_along_axis(block, idx, axis=1)
            valid = xs[:, 1:] > xs[:, :-1]
            n_distinct = valid.sum(axis=1) + 1
            for i in range(c1 - c0):
                f = c0 + i
                if n_distinct[i] <= N // 8:
                    self.coarse[f] = True
                    index[f, idx[i]] = np.concatenate([[0], np.cumsum(valid[i])])
                    uniques.append(xs[i][np.concatenate([[True], valid[i]])].astype(np.float64))
                else:
                    index[f] = idx[i]
                    if not valid[i].all():
                        self.valid_row[f] = len(tie_masks)
                        tie_masks.append(valid[i].copy())
        self.fine_features = np.flatnonzero(~self.coarse)
        self.coarse_features = np.flatnonzero(self.coarse)
        _permute_rows(index, np.concatenate([self.fine_features, self.coarse_features]))
        n_fine = self.fine_features.size
        #: ``(n_fine, N)``: example indices of each fine feature in increasing order of its values.
        self.order = index[:n_fine]
        #: ``(n_coarse, N)``: rank of each example's value among the distinct values of each coarse feature.
        self.ranks = index[n_fine:]
        self._index = index
        #: Row of the feature in ``order`` (fine) or ``ranks`` (coarse).
        self.row = np.zeros(F, dtype=np.intp)
        self.row[self.fine_features] = np.arange(n_fine)
        self.row[self.coarse_features] = np.arange(self.coarse_features.size)
        #: ``valid[valid_row[f], k]``: a split after the ``k+1`` smallest values of ``f`` is allowed.
        self.valid = np.stack(tie_masks) if tie_masks else np.ones((0, N - 1), dtype=bool)
        #: Distinct values of coarse feature ``f``: ``uniques[offsets[row[f]]:offsets[row[f] + 1]]``.
        self.offsets = np.concatenate([[0], np.cumsum([u.size for u in uniques])]).astype(np.intp)
        self.uniques = np.concatenate(uniques) if uniques else np.zeros(0)

    @property
    def nbytes(self) -> int:
        """Bytes held by the sort (not counting ``X``)."""
        return int(self._index.nbytes + self.valid.nbytes + self.uniques.nbytes)

    def _valid(self, f: int) -> npt.NDArray[np.bool_] | None:
        row = self.valid_row[f]
        return None if row < 0 else self.valid[row]

    def _n_groups(self, f: int) -> int:
        r = self.row[f]
        return int(self.offsets[r + 1] - self.offsets[r])

    def _prefix_sums(self, ws: FloatArray, f: int) -> FloatArray:
        """``S``: cumulative sums of ``ws`` in increasing order of feature ``f``.

        Per example for a fine feature ``(N,)``, per distinct value for a coarse one ``(G,)``.
        """
        if self.coarse[f]:
            return np.cumsum(np.bincount(self.ranks[self.row[f]], weights=ws, minlength=self._n_groups(f)))
        return np.cumsum(np.take(ws, self.order[self.row[f]], mode="clip"))

    def _value(self, f: int, k: int) -> float:
        """The ``k``-th smallest value of ``f`` (counted per example or per distinct value)."""
        if self.coarse[f]:
            return float(self.uniques[self.offsets[self.row[f]] + k])
        return float(self.X[self.order[self.row[f], k], f])

    # -- the search ---------------------------------------------------------------------

    def best(self, ws: FloatArray, use_interval: npt.NDArray[np.bool_]) -> WeakLearner | None:
        """The learner maximising ``r = Σ ws·h`` over all features, or None if no split exists.

        ``ws`` is ``D·y`` (``(N,)`` float64, signed weights); ``use_interval[f]`` chooses the
        interval search (eq. 5.2) instead of thresholds (eq. 4.1) for feature ``f``.
        """
        ws = np.ascontiguousarray(ws, dtype=np.float64)
        if ws.shape != (self.n_samples,):
            raise ValueError(f"weights must have shape ({self.n_samples},), got {ws.shape}")
        use_interval = np.asarray(use_interval, dtype=bool)
        total = float(ws.sum())
        scores = np.full(self.n_features, -np.inf)
        fine = self.fine_features
        step = max(1, ROUND_CHUNK_ELEMENTS // self.n_samples)
        buf = np.empty((step, self.n_samples))
        for c0 in range(0, fine.size, step):
            c1 = min(fine.size, c0 + step)
            G = buf[: c1 - c0]
            np.take(ws, self.order[c0:c1], out=G, mode="clip")  # indices are valid; clip skips checks
            np.cumsum(G, axis=1, out=G)
            feats = fine[c0:c1]
            scores[feats] = self._threshold_scores(G, feats, total)
            for r in np.flatnonzero(use_interval[feats]).tolist():
                scores[feats[r]] = _interval_best(G[r], self._valid(int(feats[r])), total)[0]
        for c in self.coarse_features.tolist():
            S = self._prefix_sums(ws, c)
            if use_interval[c]:
                scores[c] = _interval_best(S, None, total)[0]
            else:
                scores[c] = _threshold_best(S, None, total)[0]
        f = int(np.argmax(scores))
        if not np.isfinite(scores[f]):
            return None
        S = self._prefix_sums(ws, f)
        valid = self._valid(f)
        if use_interval[f]:
            _, p, i, j = _interval_best(S, valid, total)
            n = S.size
            lower = (
                -np.inf
                if i == 0
                else _between(self._value(f, i - 1), self._value(f, i), self._value(f, i - 1))
            )
            upper = (
                np.inf if j == n else _between(self._value(f, j - 1), self._value(f, j), self._value(f, j))
            )
            kind, theta = KIND_INTERVAL, lower
        else:
            _, p, k = _threshold_best(S, valid, total)
            a, b = self._value(f, k), self._value(f, k + 1)  # the split after the k+1 smallest
            kind, theta, upper = KIND_THRESHOLD, _between(a, b, b if p > 0 else a), float("nan")
        h = WeakLearner(f, kind, float(theta), float(upper), p, 0.0).predict(self.X[:, f])
        return WeakLearner(f, kind, float(theta), float(upper), p, float(ws @ h))

    def _threshold_scores(self, G: FloatArray, feats: IntArray, total: float) -> FloatArray:
        """Best ``r`` of a threshold per fine feature; ``G`` holds the prefix sums per row."""
        S = G[:, :-1]  # a split after k = 1..N−1 sorted values
        rows = np.arange(S.shape[0])
        kmax = S.argmax(axis=1)
        kmin = S.argmin(axis=1)
        smax = S[rows, kmax]
        smin = S[rows, kmin]
        tied = np.flatnonzero(self.valid_row[feats] >= 0)
        if tied.size:
            vr = self.valid_row[feats[tied]]
            inside_ties = ~(self.valid[vr, kmax[tied]] & self.valid[vr, kmin[tied]])
            for i in tied[inside_ties]:  # an extreme fell inside a run of ties: mask them out
                sv = S[i][self.valid[self.valid_row[feats[i]]]]
                smax[i], smin[i] = (sv.max(), sv.min()) if sv.size else (-np.inf, np.inf)
        # p = +1 (left side +1): r = 2 S_k − S_N; p = −1: r = S_N − 2 S_k.
        return np.maximum(2.0 * smax - total, total - 2.0 * smin)


def _threshold_best(
    S: FloatArray, valid: npt.NDArray[np.bool_] | None, total: float
) -> tuple[float, int, int]:
    """Best threshold from prefix sums ``S`` ``(n,)``: ``(r, p, k)``, the split after ``k+1`` values.

    ``valid[k]`` (``(n−1,)``) allows the split after ``k+1`` values; ``r = −inf`` if none is.
    """
    r_left = 2.0 * S[:-1] - total  # r of p = +1 (the smaller values get +1)
    if valid is not None:
        r_left = np.where(valid, r_left, np.nan)
    if r_left.size == 0 or np.isnan(r_left).all():
        return -np.inf, 1, 0
    k_pos = int(np.nanargmax(r_left))
    k_neg = int(np.nanargmin(r_left))
    if r_left[k_pos] >= -r_left[k_neg]:
        return float(r_left[k_pos]), 1, k_pos
    return float(-r_left[k_neg]), -1, k_neg


def _interval_best(
    S: FloatArray, valid: npt.NDArray[np.bool_] | None, total: float
) -> tuple[float, int, int, int]:
    """Best interval from prefix sums ``S`` ``(n,)``: ``(r, p, i, j)``.

    Cuts are ``0..n`` with ``P[0] = 0``, ``P[k] = S[k−1]``; the interval holds the sorted
    values ``i..j−1`` and both ends must be allowed cuts (0, n, or ``valid[k−1]``). The
    whole line ``(0, n)``, a constant, is excluded. ``r = −inf`` if no interval exists.
    For ``p = +1`` (inside +1) ``r = 2 (P_j − P_i) − total``, maximised by
    ``max_j P_j − min_{i<j} P_i`` (a running minimum); ``p = −1`` mirrors it.
    """
    n = S.size
    P = np.empty(n + 1)
    P[0] = 0.0
    P[1:] = S
    cut_ok = np.ones(n + 1, dtype=bool)
    if valid is not None:
        cut_ok[1:n] = valid
    lo_fill = np.where(cut_ok, P, np.inf)
    hi_fill = np.where(cut_ok, P, -np.inf)
    # Best block ending at cut j (1..n), as P_j minus the extreme start before it.
    bmax = np.full(n, -np.inf)
    bmin = np.full(n, np.inf)
    bmax[: n - 1] = np.where(cut_ok[1:n], P[1:n] - np.minimum.accumulate(lo_fill)[: n - 1], -np.inf)
    bmin[: n - 1] = np.where(cut_ok[1:n], P[1:n] - np.maximum.accumulate(hi_fill)[: n - 1], np.inf)
    if n > 1:  # a block ending at n must start at an inner cut
        bmax[n - 1] = P[n] - lo_fill[1:n].min()
        bmin[n - 1] = P[n] - hi_fill[1:n].max()
    jp, jn = int(np.argmax(bmax)), int(np.argmin(bmin))
    r_pos, r_neg = 2.0 * bmax[jp] - total, total - 2.0 * bmin[jn]
    if not (np.isfinite(r_pos) or np.isfinite(r_neg)):
        return -np.inf, 1, 0, 0
    p, j = (1, jp + 1) if r_pos >= r_neg else (-1, jn + 1)
    first = 1 if j == n else 0
    starts = lo_fill[first:j] if p > 0 else -hi_fill[first:j]
    i = first + int(np.argmin(starts))
    return float(max(r_pos, r_neg)), p, i, j
