"""Binary boosting on single-valued features: discrete AdaBoost (book Fig. 3.3) and
generalized AdaBoost (Fig. 4.2), with threshold (eq. 3.1/4.1) and interval (eq. 5.2) learners.

Both boosters follow scikit-learn's manners without depending on it: ``__init__`` only stores
parameters, :meth:`~AdaBoost.fit` returns ``self``, fitted state ends in ``_``, an unfitted
booster raises :class:`~knowledge.errors.NotFittedError`.

Training (both figures):

* ``D_1(n) = 1/(2l)`` for the ``l`` positives and ``1/(2m)`` for the ``m`` negatives
  (``balanced=True``; with ``balanced=False`` ``D_1`` is uniform, as in Fig. 2.2);
* each round the weights are normalised, the weak learner with the lowest weighted error
  ``ε`` — equivalently the highest ``r = Σ D y h``, ``ε = (1 − r)/2`` — is found exactly over
  all features (:class:`~knowledge.learning.weak.SortedFeatures`), and the weights updated;
* discrete: ``β = ε/(1 − ε)``, ``α = log(1/β)``, ``D ← D·β^{1−|h−y|}``;
  generalized: ``α = ½ log((1 + r)/(1 − r))`` (eq. 2.4), ``D ← D·exp(−α y h)``.

Training stops early (``stop_reason_``) when the best learner is no better than chance
(``ε ≥ ½``, ``r ≤ 0``; that learner is not added), or when it is perfect (``ε = 0``): it is
added with α computed from ``ε = 1e-10`` (α ≈ 23 discrete, ≈ 11.5 generalized) and training
stops, since every later round would see the same weights again.

Both expose the same real-valued output ``F(x) = Σ_t c_t h_t(x)`` with ``h_t = ±1``, whose sign
is the decision (``F ≥ 0`` → positive, the ``≥`` of Fig. 3.3). For the generalized booster
``c_t = α_t``. For the discrete one the book's vote ``Σ α_t h_t ≥ ½ Σ α_t`` (``h_t ∈ {0, 1}``)
is shifted so that 0 is the boundary: ``F = Σ α_t h_t − ½ Σ α_t = ½ Σ α_t (2h_t − 1)``, i.e.
``c_t = α_t/2``. Since the discrete ``α = log((1−ε)/ε)`` is twice the generalized one for
``r = 1 − 2ε``, and both updates give the same normalised weights, the two boosters pick the
same learners and produce the same ``F``; they differ in the bookkeeping the book prints.
The confidence ``C⁺ = e^F/(e^{−F} + e^F)`` (eq. 4.2–4.4) is computed from ``F`` for both.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, ClassVar, Self

import numba
import numpy as np
import numpy.typing as npt

from knowledge.errors import NotFittedError
from knowledge.learning.weak import (
    KIND_INTERVAL,
    KIND_NAMES,
    KIND_THRESHOLD,
    FloatArray,
    SortedFeatures,
    as_feature_matrix,
    inside_form,
)

#: Weighted error used in place of 0 for a perfect learner (caps α).
MIN_ERROR = 1e-10
#: ``r`` at or below this is "no better than chance".
CHANCE_R = 1e-12
#: Elements (examples × rounds) evaluated at once when predicting.

WeakSpec = str | Sequence[str] | Sequence[bool] | npt.NDArray[Any]

STATE_ARRAYS = (
    "weak_feature",
    "weak_kind",
    "weak_threshold",
    "weak_upper",
    "weak_polarity",
    "alpha",
    "weak_error",
)


def binary_labels(y: npt.ArrayLike, n: int) -> npt.NDArray[np.bool_]:
    """``y`` as a boolean "is positive" array ``(n,)``; accepts bool, {0, 1} or {−1, +1}."""
    a = np.asarray(y)
    if a.shape != (n,):
        raise ValueError(f"y must have shape ({n},) to match X, got {a.shape}")
    if a.dtype == bool:
        pos = a
    elif a.dtype.kind in "iuf":
        values = set(np.unique(a).tolist())
        if not (values <= {0, 1} or values <= {-1, 1}):
            raise ValueError(
                f"y must be binary: bool, 0/1 or -1/+1; got the values {sorted(values)[:10]}. "
                "For several classes use knowledge.learning.decision_list.DecisionList"
            )
        pos = a == 1
    else:
        raise ValueError(f"y must be bool, 0/1 or -1/+1, got dtype {a.dtype}")
    if pos.all() or not pos.any():
        raise ValueError("y holds only one class: boosting needs positive and negative examples")
    return pos


def resolve_weak(weak: WeakSpec, n_features: int) -> npt.NDArray[np.bool_]:
    """The per-feature choice "use the interval learner" ``(F,)`` bool from a ``weak`` parameter.

    ``weak`` is ``"threshold"``, ``"interval"``, ``"both"`` (same as ``"interval"``: an interval
    with one open end is a threshold, so the interval search already finds the best of both),
    a boolean mask of length F (True → interval) or a sequence of F kind names.
    """
    if isinstance(weak, str):
        if weak == "threshold":
            return np.zeros(n_features, dtype=bool)
        if weak in ("interval", "both"):
            return np.ones(n_features, dtype=bool)
        raise ValueError(
            f'weak must be "threshold", "interval" or "both" (or one kind per feature), got {weak!r}'
        )
    arr = np.asarray(weak)
    if arr.shape != (n_features,):
        raise ValueError(
            f"a per-feature weak choice needs one entry per feature ({n_features}), got shape {arr.shape}; "
            'use weak="both" to try both kinds on every feature'
        )
    if arr.dtype == bool:
        return arr.copy()
    if arr.dtype.kind == "U":
        unknown = sorted(set(arr.tolist()) - {"threshold", "interval"})
        if unknown:
            raise ValueError(f'per-feature weak kinds must be "threshold" or "interval", got {unknown}')
        return np.asarray(arr == "interval")
    raise ValueError(
        f"weak must be a kind name, a boolean mask or kind names per feature, got dtype {arr.dtype}"
    )


class AdaBoost:
    """Common machinery of :class:`DiscreteAdaBoost` and :class:`GeneralizedAdaBoost`.

    Parameters: ``n_rounds`` = T, the maximum number of weak learners; ``weak`` the learner
    kind (see :func:`resolve_weak`); ``balanced`` the initial weights (see the module doc).

    Fitted attributes, each ``(T_fit,)`` with ``T_fit ≤ n_rounds`` the rounds actually done:
    ``weak_feature_`` (column of X), ``weak_kind_`` (0 threshold, 1 interval),
    ``weak_threshold_`` (θ, or θ¹ of an interval, may be −inf), ``weak_upper_`` (θ² of an
    interval, may be +inf; NaN for thresholds), ``weak_polarity_`` (p = ±1), ``alpha_`` (the
    book's learner weights), ``weak_error_`` (ε_t, weighted by the normalised D_t).
    Also ``n_features_in_``, ``n_rounds_`` (= T_fit), ``train_error_`` (fraction of training
    examples misclassified by the final classifier), ``stop_reason_`` ("n_rounds",
    "perfect" or "chance") and ``classes_`` = ``[False, True]``.
    """

    booster_type: ClassVar[str] = ""
    #: F = Σ coef_scale·α_t·h_t (±1 outputs).
    coef_scale: ClassVar[float] = 1.0

    def __init__(self, n_rounds: int = 100, weak: WeakSpec = "threshold", *, balanced: bool = True) -> None:
        self.n_rounds = n_rounds
        self.weak = weak
        self.balanced = balanced

    def get_params(self) -> dict[str, Any]:
        """The constructor parameters (``weak`` as a list if it is per-feature)."""
        weak = self.weak if isinstance(self.weak, str) else np.asarray(self.weak).tolist()
        return {"n_rounds": self.n_rounds, "weak": weak, "balanced": self.balanced}

    def __repr__(self) -> str:
        params = ", ".join(
            f"{k}={v!r}" for k, v in self.get_params().items() if k != "weak" or isinstance(v, str)
        )
        return f"{type(self).__name__}({params})"

    # -- training -----------------------------------------------------------------------

    def fit(
        self,
        X: npt.ArrayLike,
        y: npt.ArrayLike,
        sample_weight: npt.ArrayLike | None = None,
        *,
        presorted: SortedFeatures | None = None,
        on_round: Callable[[int], None] | None = None,
    ) -> Self:
        """Learn up to ``n_rounds`` weak learners from ``X`` ``(N, F)`` and binary ``y`` ``(N,)``.

        ``sample_weight`` ``(N,)`` ≥ 0 scales the initial weights (within each class when
        ``balanced``). ``presorted`` is a :class:`SortedFeatures` already built from this
        very ``X``; pass one to share the sort between boosters trained on the same matrix.
        ``on_round(t)`` is called after each round ``t = 1..`` (for progress reports).
        """
        if not isinstance(self.n_rounds, int | np.integer) or self.n_rounds < 1:
            raise ValueError(f"n_rounds must be a positive integer, got {self.n_rounds!r}")
        if presorted is None:
            presorted = SortedFeatures(X)
        elif np.shape(X) != (presorted.n_samples, presorted.n_features):
            raise ValueError(
                f"presorted was built from a {presorted.n_samples}×{presorted.n_features} matrix, "
                f"X is {np.shape(X)}: build SortedFeatures(X) from the X you fit on"
            )
        sf = presorted
        N, F = sf.n_samples, sf.n_features
        pos = binary_labels(y, N)
        ysign = np.where(pos, 1.0, -1.0)
        use_interval = resolve_weak(self.weak, F)
        D = self._initial_weights(pos, sample_weight)

        feats: list[int] = []
        kinds: list[int] = []
        thetas: list[float] = []
        uppers: list[float] = []
        pols: list[int] = []
        alphas: list[float] = []
        errors: list[float] = []
        Ftrain = np.zeros(N)
        stop = "n_rounds"
        for t in range(int(self.n_rounds)):
            D /= D.sum()
            learner = sf.best(D * ysign, use_interval)
            if learner is None or learner.r <= CHANCE_R:
                if t == 0:
                    raise ValueError(
                        "no weak learner is better than chance on these data (are all features constant?)"
                    )
                stop = "chance"
                break
            h = learner.predict(sf.X[:, learner.feature])
            alpha, error, D, perfect = self._update(D, ysign, h)
            feats.append(learner.feature)
            kinds.append(learner.kind)
            thetas.append(learner.threshold)
            uppers.append(learner.upper)
            pols.append(learner.polarity)
            alphas.append(alpha)
            errors.append(error)
            Ftrain += self.coef_scale * alpha * h
            if on_round is not None:
                on_round(t + 1)
            if perfect:
                stop = "perfect"
                break
        self._set_fitted(
            np.array(feats, dtype=np.int32),
            np.array(kinds, dtype=np.uint8),
            np.array(thetas, dtype=np.float64),
            np.array(uppers, dtype=np.float64),
            np.array(pols, dtype=np.int8),
            np.array(alphas, dtype=np.float64),
            np.array(errors, dtype=np.float64),
            n_features=F,
        )
        self.train_error_ = float(np.mean((Ftrain >= 0) != pos))
        self.stop_reason_ = stop
        return self

    def _initial_weights(self, pos: npt.NDArray[np.bool_], sample_weight: npt.ArrayLike | None) -> FloatArray:
        N = pos.shape[0]
        if sample_weight is None:
            w = np.ones(N)
        else:
            w = np.asarray(sample_weight, dtype=np.float64)
            if w.shape != (N,) or not np.isfinite(w).all() or (w < 0).any():
                raise ValueError(f"sample_weight must be ({N},) finite and ≥ 0, got shape {w.shape}")
        if self.balanced:  # Fig. 3.3 / 4.2: each class starts with half of the weight
            wp, wn = w[pos].sum(), w[~pos].sum()
            if wp <= 0 or wn <= 0:
                raise ValueError("sample_weight gives one class zero total weight")
            return np.where(pos, w / (2 * wp), w / (2 * wn))
        if w.sum() <= 0:
            raise ValueError("sample_weight sums to zero")
        return w / w.sum()

    def _update(
        self, D: FloatArray, ysign: FloatArray, h: npt.NDArray[np.int8]
    ) -> tuple[float, float, FloatArray, bool]:
        """One round's weight α, weighted error ε, next (unnormalised) weights, and "perfect"."""
        raise NotImplementedError

    def _set_fitted(
        self,
        feature: npt.NDArray[np.int32],
        kind: npt.NDArray[np.uint8],
        threshold: FloatArray,
        upper: FloatArray,
        polarity: npt.NDArray[np.int8],
        alpha: FloatArray,
        error: FloatArray,
        *,
        n_features: int,
    ) -> None:
        self.weak_feature_ = feature
        self.weak_kind_ = kind
        self.weak_threshold_ = threshold
        self.weak_upper_ = upper
        self.weak_polarity_ = polarity
        self.alpha_ = alpha
        self.weak_error_ = error
        self.n_features_in_ = int(n_features)
        self.n_rounds_ = int(feature.shape[0])
        self.classes_ = np.array([False, True])
        self._lo, self._hi, self._s = inside_form(kind, threshold, upper, polarity)
        self._coef = self.coef_scale * alpha

    # -- prediction ---------------------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "alpha_"):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet: call fit(X, y) first (or load a model)"
            )

    def _check_input(self, X: npt.ArrayLike) -> npt.NDArray[np.floating]:
        self._check_fitted()
        A = as_feature_matrix(X)
        if A.shape[1] != self.n_features_in_:
            raise ValueError(f"X has {A.shape[1]} features, this booster was fitted on {self.n_features_in_}")
        return A

    def decision_function(self, X: npt.ArrayLike) -> FloatArray:
        """``F(x) = Σ_t c_t h_t(x)`` for ``X`` ``(N, F)``: ``(N,)``; F ≥ 0 is a positive decision."""
        A = np.ascontiguousarray(self._check_input(X))
        w2 = 2.0 * self._s * self._coef
        bias = -float(np.sum(self._s * self._coef))
        return _weighted_votes(A, self.weak_feature_.astype(np.int64), self._lo, self._hi, w2, bias)

    def predict(self, X: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """True where ``F(x) ≥ 0`` (positive), ``(N,)`` bool."""
        return self.decision_function(X) >= 0

    def predict_proba(self, X: npt.ArrayLike) -> FloatArray:
        """``(N, 2)``: column 0 is ``C⁻ = P(y=−1|x)`` (eq. 4.4), column 1 ``C⁺ = P(y=+1|x)`` (4.2–4.3).

        The columns follow ``classes_ = [False, True]`` as in scikit-learn; the decision list
        uses column 1. ``C⁺ = e^F/(e^{−F} + e^F) = (1 + tanh F)/2``.
        """
        th = np.tanh(self.decision_function(X))
        return np.column_stack([0.5 * (1.0 - th), 0.5 * (1.0 + th)])

    def staged_decision_function(self, X: npt.ArrayLike) -> Iterator[FloatArray]:
        """``F`` after each round ``t = 1..T_fit``, each ``(N,)``."""
        A = self._check_input(X)
        vals = A[:, self.weak_feature_]
        H = np.where((self._lo < vals) & (vals < self._hi), self._s, -self._s) * self._coef
        np.cumsum(H, axis=1, out=H)
        for t in range(self.n_rounds_):
            yield H[:, t].copy()

    def staged_predict(self, X: npt.ArrayLike) -> Iterator[npt.NDArray[np.bool_]]:
        """The decision ``F ≥ 0`` after each round, each ``(N,)`` bool."""
        for F in self.staged_decision_function(X):
            yield F >= 0

    # -- inspection ---------------------------------------------------------------------

    def used_features(self) -> npt.NDArray[np.intp]:
        """Sorted unique columns of X the weak learners look at."""
        self._check_fitted()
        return np.unique(self.weak_feature_).astype(np.intp)

    def feature_importance(self) -> FloatArray:
        """Sum of α over the learners of each feature, ``(n_features_in_,)``.

        Sort it to list the most important features (book Tables 3.5, 8.6 rank single
        learners by α; ``np.argsort(-alpha_)`` with ``weak_feature_`` gives that list).
        """
        self._check_fitted()
        return np.bincount(self.weak_feature_, weights=self.alpha_, minlength=self.n_features_in_).astype(
            np.float64
        )

    # -- state for model files ----------------------------------------------------------

    def get_state(self) -> tuple[dict[str, Any], dict[str, npt.NDArray[Any]]]:
        """JSON-able metadata and the named arrays that rebuild this fitted booster."""
        self._check_fitted()
        meta: dict[str, Any] = {
            "type": self.booster_type,
            "params": self.get_params(),
            "n_features_in": self.n_features_in_,
            "n_rounds_fitted": self.n_rounds_,
            "train_error": getattr(self, "train_error_", None),
            "stop_reason": getattr(self, "stop_reason_", None),
        }
        arrays: dict[str, npt.NDArray[Any]] = {
            "weak_feature": self.weak_feature_,
            "weak_kind": self.weak_kind_,
            "weak_threshold": self.weak_threshold_,
            "weak_upper": self.weak_upper_,
            "weak_polarity": self.weak_polarity_,
            "alpha": self.alpha_,
            "weak_error": self.weak_error_,
        }
        return meta, arrays

    def reindexed(self, features: Sequence[int] | npt.NDArray[np.integer]) -> Self:
        """A copy that reads column ``i`` of its input where this one read column ``features[i]``.

        ``features`` must contain every used feature; a per-feature ``weak`` is re-indexed too.
        """
        self._check_fitted()
        feats = np.asarray(features, dtype=np.intp)
        lookup = np.full(self.n_features_in_, -1, dtype=np.intp)
        lookup[feats] = np.arange(feats.size)
        missing = sorted(set(self.used_features().tolist()) - set(feats.tolist()))
        if missing:
            raise ValueError(f"features {missing} are used by this booster but not kept")
        new = copy.deepcopy(self)
        if not isinstance(self.weak, str):
            new.weak = np.asarray(self.weak)[feats].tolist()
        new._set_fitted(
            lookup[self.weak_feature_].astype(np.int32),
            self.weak_kind_,
            self.weak_threshold_,
            self.weak_upper_,
            self.weak_polarity_,
            self.alpha_,
            self.weak_error_,
            n_features=feats.size,
        )
        return new


class DiscreteAdaBoost(AdaBoost):
    """Discrete AdaBoost of Fig. 3.3: learners ``h ∈ {0, 1}``, ``α_t = log(1/β_t)``.

    ``decision_function`` is the book's weighted vote shifted so 0 is the boundary:
    ``F = Σ α_t h_t − ½ Σ α_t`` (see the module doc). ``beta_`` = β_t.
    """

    booster_type = "discrete"
    coef_scale = 0.5

    def _update(
        self, D: FloatArray, ysign: FloatArray, h: npt.NDArray[np.int8]
    ) -> tuple[float, float, FloatArray, bool]:
        miss = (h > 0) != (ysign > 0)
        error = float(D[miss].sum())  # ε = Σ D |h − y| with h, y ∈ {0, 1}
        beta = max(error, MIN_ERROR) / (1.0 - max(error, MIN_ERROR))
        return float(np.log(1.0 / beta)), error, np.where(miss, D, D * beta), not miss.any()

    @property
    def beta_(self) -> FloatArray:
        """β_t = ε_t/(1 − ε_t) of each round (with ε floored at 1e-10), ``(T_fit,)``."""
        self._check_fitted()
        return np.exp(-self.alpha_)


class GeneralizedAdaBoost(AdaBoost):
    """Generalized AdaBoost of Fig. 4.2: ``h ∈ {−1, +1}``, ``α_t = ½ log((1 + r_t)/(1 − r_t))``.

    ``weak`` may be ``"threshold"`` (eq. 4.1), ``"interval"`` (eq. 5.2), ``"both"`` or a
    per-feature choice (e.g. intervals for object counts, thresholds for laser features).
    ``weak_r_`` = r_t = 1 − 2ε_t.
    """

    booster_type = "generalized"

    def _update(
        self, D: FloatArray, ysign: FloatArray, h: npt.NDArray[np.int8]
    ) -> tuple[float, float, FloatArray, bool]:
        margin = ysign * h
        r = float(D @ margin)
        rc = min(r, 1.0 - 2.0 * MIN_ERROR)
        alpha = 0.5 * float(np.log((1.0 + rc) / (1.0 - rc)))
        return alpha, 0.5 * (1.0 - r), D * np.exp(-alpha * margin), bool((margin > 0).all())

    @property
    def weak_r_(self) -> FloatArray:
        """r_t = Σ D_t y h_t of each round (eq. 2.5), ``(T_fit,)``."""
        self._check_fitted()
        return 1.0 - 2.0 * self.weak_error_


BOOSTER_TYPES: dict[str, type[AdaBoost]] = {
    DiscreteAdaBoost.booster_type: DiscreteAdaBoost,
    GeneralizedAdaBoost.booster_type: GeneralizedAdaBoost,
}


def booster_from_state(meta: Mapping[str, Any], arrays: Mapping[str, npt.NDArray[Any]]) -> AdaBoost:
    """Rebuild a fitted booster from :meth:`AdaBoost.get_state`; ValueError if inconsistent."""
    kind = meta.get("type")
    if kind not in BOOSTER_TYPES:
        raise ValueError(f"unknown booster type {kind!r}; known: {sorted(BOOSTER_TYPES)}")
    missing = [k for k in STATE_ARRAYS if k not in arrays]
    if missing:
        raise ValueError(f"booster arrays missing: {missing}")
    arr = {k: np.asarray(arrays[k]) for k in STATE_ARRAYS}
    T = arr["alpha"].shape
    for k, a in arr.items():
        if a.shape != T or a.ndim != 1:
            raise ValueError(f"booster array {k!r} has shape {a.shape}, expected {T} like 'alpha'")
        if a.dtype.kind not in "iuf":
            raise ValueError(f"booster array {k!r} must be numeric, got dtype {a.dtype}")
    if T[0] == 0:
        raise ValueError("a booster needs at least one weak learner")
    n_features = int(meta.get("n_features_in", -1))
    feat = arr["weak_feature"]
    if n_features < 1 or feat.min() < 0 or feat.max() >= n_features:
        raise ValueError(
            f"weak_feature indices {feat.min()}..{feat.max()} do not fit n_features_in={n_features}"
        )
    if not set(np.unique(arr["weak_kind"]).tolist()) <= {KIND_THRESHOLD, KIND_INTERVAL}:
        raise ValueError(f"weak_kind must be 0 ({KIND_NAMES[0]}) or 1 ({KIND_NAMES[1]})")
    if not set(np.unique(arr["weak_polarity"]).tolist()) <= {-1, 1}:
        raise ValueError("weak_polarity must be -1 or +1")
    if not np.isfinite(arr["alpha"]).all():
        raise ValueError("alpha must be finite")
    params = dict(meta.get("params") or {})
    booster = BOOSTER_TYPES[kind](
        n_rounds=int(params.get("n_rounds") or T[0]),
        weak=params.get("weak", "threshold"),
        balanced=bool(params.get("balanced", True)),
    )
    booster._set_fitted(
        feat.astype(np.int32),
        arr["weak_kind"].astype(np.uint8),
        arr["weak_threshold"].astype(np.float64),
        arr["weak_upper"].astype(np.float64),
        arr["weak_polarity"].astype(np.int8),
        arr["alpha"].astype(np.float64),
        arr["weak_error"].astype(np.float64),
        n_features=n_features,
    )
    if meta.get("train_error") is not None:
        booster.train_error_ = float(meta["train_error"])
    if meta.get("stop_reason") is not None:
        booster.stop_reason_ = str(meta["stop_reason"])
    return booster


@numba.njit(cache=True, nogil=True)
def _weighted_votes(
    A: npt.NDArray[np.floating],
    feature: npt.NDArray[np.int64],
    lo: npt.NDArray[np.floating],
    hi: npt.NDArray[np.floating],
    w2: FloatArray,
    bias: float,
) -> FloatArray:  # pragma: no cover - compiled
    """``bias + Σ_t w2[t]·[lo[t] < A[i, feature[t]] < hi[t]]`` per row: one pass over each row."""
    n = A.shape[0]
    out = np.empty(n)
    for i in range(n):
        acc = bias
        for t in range(feature.shape[0]):
            v = A[i, feature[t]]
            if lo[t] < v and v < hi[t]:
                acc += w2[t]
        out[i] = acc
    return out
