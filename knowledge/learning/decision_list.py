"""Decision lists of one-vs-all binary boosters (book Sect. 3.3) and the probabilistic
decision list (Sect. 4.3, eq. 4.5).

One binary booster per class is trained with that class as positives and all others as
negatives. The list consults them in an order; the last class is the default and its booster
is never consulted (``C_K⁺ = 1``). With the confidences ``C_k⁺`` of the boosters in list order,
the probabilistic list outputs the histogram (eq. 4.5)

    p(k) = C_k⁺ · Π_{j<k} (1 − C_j⁺),

whose bins sum to 1. Two decision rules:

* probabilistic (``probabilistic=True``, the default; Sect. 4.3): the class of the largest
  bin, ``argmax_k p(k)``;
* sequential (Sect. 3.3, Fig. 3.4): the first class whose booster says positive
  (``C⁺ ≥ ½``, i.e. ``F ≥ 0``), else the default class — :meth:`DecisionList.predict_sequential`.

If the first booster with ``C⁺ ≥ ½`` is the k-th, no later bin exceeds ``p(k)`` (together
they hold ``(1 − C_k⁺) Π_{j<k}(1 − C_j⁺) ≤ p(k)``), so the two rules disagree only when an
earlier, individually negative bin is larger, or when no booster says positive.

The order is chosen by ``order=``: ``"best"`` tries every permutation of the classes and keeps
the one with the highest accuracy (on ``selection_data`` if given, else on the training data;
Sect. 3.3); ``"heuristic"`` sorts the boosters by training error, lowest first (Sect. 5.5);
or an explicit sequence of all class names. The book names an order by its first K−1 classes
("room-doorway" for room → doorway → corridor): :func:`order_name`.
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Self

import numpy as np
import numpy.typing as npt

from knowledge.errors import NotFittedError
from knowledge.learning.boosting import AdaBoost, GeneralizedAdaBoost, booster_from_state
from knowledge.learning.weak import FloatArray, SortedFeatures, as_feature_matrix

#: "best" enumerates K! orders; beyond this many classes use "heuristic" or an explicit order.
MAX_BEST_CLASSES = 7

BoosterFactory = Callable[[], AdaBoost]
ClassSpec = Sequence[str] | Mapping[int, str]
Order = tuple[str, ...]


def order_name(order: Sequence[str]) -> str:
    """The book's name of an order: its first K−1 classes joined by "-" ("room-doorway")."""
    return "-".join(order[:-1])


def class_names(y: npt.ArrayLike, classes: ClassSpec | None = None) -> npt.NDArray[np.str_]:
    """Labels ``y`` ``(N,)`` as class names.

    ``y`` holds class names, or integers with ``classes`` naming them: a sequence (``y`` indexes
    it) or a mapping code → name (e.g. :data:`knowledge.labels.CLASS_NAMES` for label-image
    codes). With names and a sequence ``classes``, every name must be in ``classes``.
    """
    a = np.asarray(y)
    if a.ndim != 1:
        raise ValueError(f"labels must be a 1-D array, got shape {a.shape}")
    if a.dtype.kind in "USO":
        names = a.astype(str)
        if classes is not None:
            known = set(classes.values()) if isinstance(classes, Mapping) else set(classes)
            unknown = sorted(set(names.tolist()) - known)
            if unknown:
                raise ValueError(f"labels {unknown[:5]} are not among the classes {sorted(known)}")
        return names
    if a.dtype.kind not in "iu":
        raise ValueError(f"labels must be class names or integer codes, got dtype {a.dtype}")
    if classes is None:
        raise ValueError(
            "integer labels need classes=: a list of names (y indexes it) or a code → name mapping"
        )
    if isinstance(classes, Mapping):
        unknown = sorted(set(np.unique(a).tolist()) - set(classes))
        if unknown:
            raise ValueError(f"label codes {unknown[:5]} are not in the classes mapping {dict(classes)}")
        lookup = dict(classes)
        return np.array([lookup[int(v)] for v in a], dtype=str) if a.size else np.array([], dtype=str)
    names_list = list(classes)
    if a.size and (a.min() < 0 or a.max() >= len(names_list)):
        raise ValueError(
            f"integer labels must index classes (0..{len(names_list) - 1}), got {a.min()}..{a.max()}"
        )
    return np.asarray(names_list, dtype=str)[a]


def histogram(confidences: FloatArray) -> FloatArray:
    """Eq. 4.5 for ``C⁺`` of the first K−1 boosters in list order ``(N, K−1)``: ``(N, K)`` in list order.

    ``p(k) = C_k⁺ Π_{j<k} (1 − C_j⁺)`` and the last bin ``Π_{j<K} (1 − C_j⁺)`` (``C_K⁺ = 1``).
    """
    C = np.asarray(confidences, dtype=np.float64)
    N, K1 = C.shape
    rest = np.ones((N, K1 + 1))
    np.cumprod(1.0 - C, axis=1, out=rest[:, 1:])  # rest[:, k] = Π_{j<k} (1 − C_j)
    P = rest.copy()
    P[:, :K1] *= C
    return P


def sequential_index(confidences: FloatArray) -> npt.NDArray[np.intp]:
    """Position in the list of the sequential decision: the first ``C⁺ ≥ ½``, else K−1."""
    C = np.asarray(confidences)
    positive = C >= 0.5
    first = np.argmax(positive, axis=1)
    return np.where(positive.any(axis=1), first, C.shape[1]).astype(np.intp)


class DecisionList:
    """A (probabilistic) decision list of one-vs-all binary boosters.

    ``booster`` makes an unfitted binary booster (default ``GeneralizedAdaBoost()``; e.g.
    ``functools.partial(GeneralizedAdaBoost, n_rounds=50)``); ``order`` is ``"best"``,
    ``"heuristic"`` or a sequence of all class names; ``probabilistic`` picks the decision
    rule of :meth:`predict` and of the order search (see the module doc).

    Fitted attributes: ``classes_`` (class names, ``(K,)``), ``boosters_`` (class → booster;
    every class's, including the default's), ``order_`` (tuple of all K names, the
    default last), ``order_scores_`` (``[(order, accuracy), ...]``, best first; every
    permutation for "best", the chosen order otherwise), ``train_errors_`` (class → training
    error of its booster), ``selection_`` ("validation" or "training": the data the
    accuracies were measured on).
    """

    def __init__(
        self,
        booster: BoosterFactory | None = None,
        *,
        order: str | Sequence[str] = "best",
        probabilistic: bool = True,
    ) -> None:
        self.booster = booster
        self.order = order
        self.probabilistic = probabilistic

    @property
    def order_mode(self) -> str:
        """ "best", "heuristic" or "explicit"."""
        return self.order if isinstance(self.order, str) else "explicit"

    def _make_booster(self) -> AdaBoost:
        return (self.booster or GeneralizedAdaBoost)()

    # -- training -----------------------------------------------------------------------

    def fit(
        self,
        X: npt.ArrayLike,
        y: npt.ArrayLike,
        *,
        classes: ClassSpec | None = None,
        selection_data: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        sample_weight: npt.ArrayLike | None = None,
        progress: Callable[[str, int, int], None] | None = None,
    ) -> Self:
        """Train one booster per class on ``X`` ``(N, F)``, ``y`` ``(N,)``, then choose the order.

        ``y`` and the labels of ``selection_data = (X_val, y_val)`` are class names or integer
        codes named by ``classes`` (see :func:`class_names`). ``classes_`` lists the classes
        present in ``y``, in the order of ``classes`` (sorted names without it).
        """
        if isinstance(self.order, str) and self.order not in ("best", "heuristic"):
            raise ValueError(
                f'order must be "best", "heuristic" or a sequence of class names, got {self.order!r}'
            )
        A = as_feature_matrix(X)
        names = class_names(y, classes)
        if names.shape[0] != A.shape[0]:
            raise ValueError(f"y has {names.shape[0]} labels for {A.shape[0]} examples")
        present = set(names.tolist())
        if classes is None:
            ordered = sorted(present)
        else:
            listed = [classes[k] for k in sorted(classes)] if isinstance(classes, Mapping) else list(classes)
            ordered = [c for c in dict.fromkeys(listed) if c in present]
        if len(ordered) < 2:
            raise ValueError(f"a decision list needs at least two classes in y, got {ordered}")
        K = len(ordered)
        if not isinstance(self.order, str):
            explicit = tuple(str(c) for c in self.order)
            if sorted(explicit) != sorted(ordered):
                raise ValueError(
                    f"an explicit order must list every class once: got {list(explicit)}, classes {ordered}"
                )
        elif self.order == "best" and K > MAX_BEST_CLASSES:
            raise ValueError(
                f'order="best" tries all {K}! orders; with {K} classes use order="heuristic" or give the order'
            )

        sf = SortedFeatures(A)
        self.classes_ = np.asarray(ordered, dtype=str)
        self.boosters_ = {}
        for c in ordered:
            booster = self._make_booster()
            report = None
            if progress is not None:
                total = int(booster.get_params()["n_rounds"])

                def report(t: int, _c: str = c, _total: int = total) -> None:
                    progress(f"boosting {_c}", t, _total)

            self.boosters_[c] = booster.fit(A, names == c, sample_weight, presorted=sf, on_round=report)
        del sf
        self.train_errors_ = {c: float(b.train_error_) for c, b in self.boosters_.items()}

        if selection_data is not None:
            Xs = as_feature_matrix(selection_data[0], what="selection X")
            ys = class_names(selection_data[1], classes)
            if ys.shape[0] != Xs.shape[0]:
                raise ValueError(f"selection_data has {ys.shape[0]} labels for {Xs.shape[0]} examples")
            self.selection_ = "validation"
        else:
            Xs, ys = A, names
            self.selection_ = "training"
        truth = np.array([ordered.index(c) if c in ordered else -1 for c in ys.tolist()], dtype=np.intp)
        C = np.column_stack([self.boosters_[c].predict_proba(Xs)[:, 1] for c in ordered])

        candidates: list[tuple[int, ...]]
        if self.order == "best":
            candidates = list(itertools.permutations(range(K)))
        elif self.order == "heuristic":
            candidates = [tuple(sorted(range(K), key=lambda k: self.train_errors_[ordered[k]]))]
        else:
            candidates = [tuple(ordered.index(c) for c in self.order)]
        scored = [(perm, self._accuracy(C, truth, perm)) for perm in candidates]
        scored.sort(key=lambda ps: -ps[1])  # stable: equal scores keep enumeration order
        self.order_scores_ = [(tuple(ordered[k] for k in perm), acc) for perm, acc in scored]
        self.order_ = self.order_scores_[0][0]
        return self

    def _accuracy(self, C: FloatArray, truth: npt.NDArray[np.intp], perm: tuple[int, ...]) -> float:
        if truth.size == 0:
            return float("nan")
        consulted = C[:, list(perm[:-1])]
        pos = np.argmax(histogram(consulted), axis=1) if self.probabilistic else sequential_index(consulted)
        return float(np.mean(np.asarray(perm)[pos] == truth))

    # -- prediction ---------------------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "order_"):
            raise NotFittedError(
                "this DecisionList is not fitted yet: call fit(X, y) first (or load a place model)"
            )

    def _list_confidences(self, X: npt.ArrayLike) -> tuple[FloatArray, npt.NDArray[np.intp]]:
        """``C⁺`` of the consulted boosters in list order ``(N, K−1)``, and the list → ``classes_`` index."""
        self._check_fitted()
        A = as_feature_matrix(X)
        C = np.column_stack([self.boosters_[c].predict_proba(A)[:, 1] for c in self.order_[:-1]])
        where = np.array([int(np.flatnonzero(self.classes_ == c)[0]) for c in self.order_], dtype=np.intp)
        return C, where

    def predict_proba(self, X: npt.ArrayLike) -> FloatArray:
        """The histogram of eq. 4.5 for ``X`` ``(N, F)``: ``(N, K)`` in ``classes_`` order, rows sum to 1."""
        C, where = self._list_confidences(X)
        P = histogram(C)
        out = np.empty_like(P)
        out[:, where] = P
        return out

    def predict(self, X: npt.ArrayLike) -> npt.NDArray[np.str_]:
        """Class names ``(N,)``: the largest bin of :meth:`predict_proba` (the probabilistic
        list's decision), or :meth:`predict_sequential` when ``probabilistic=False``."""
        if not self.probabilistic:
            return self.predict_sequential(X)
        P = self.predict_proba(X)
        return self.classes_[np.argmax(P, axis=1)]

    def predict_sequential(self, X: npt.ArrayLike) -> npt.NDArray[np.str_]:
        """Class names ``(N,)`` by the strict rule of Fig. 3.4: the first booster in the list with
        ``C⁺ ≥ ½`` decides; if none does, the default (last) class."""
        C, where = self._list_confidences(X)
        return self.classes_[where[sequential_index(C)]]

    def score(self, X: npt.ArrayLike, y: npt.ArrayLike, *, classes: ClassSpec | None = None) -> float:
        """Fraction of ``X`` whose :meth:`predict` equals ``y`` (names or codes as in :meth:`fit`)."""
        truth = class_names(y, classes)
        return float(np.mean(self.predict(X) == truth))

    # -- inspection ---------------------------------------------------------------------

    def used_features(self) -> npt.NDArray[np.intp]:
        """Sorted unique feature columns used by the boosters the list consults (not the default's)."""
        self._check_fitted()
        used = [self.boosters_[c].used_features() for c in self.order_[:-1]]
        return np.unique(np.concatenate(used)).astype(np.intp)

    def all_used_features(self) -> npt.NDArray[np.intp]:
        """Sorted unique feature columns used by every booster, the default class's included.

        These are needed to score other orders (:meth:`order_accuracies`); prediction needs
        only :meth:`used_features`.
        """
        self._check_fitted()
        used = [b.used_features() for b in self.boosters_.values()]
        return np.unique(np.concatenate(used)).astype(np.intp)

    def order_accuracies(
        self, X: npt.ArrayLike, y: npt.ArrayLike, *, classes: ClassSpec | None = None
    ) -> list[tuple[tuple[str, ...], float]]:
        """Accuracy of EVERY order of the classes on ``(X, y)``, best first (the book's Tables 3.1–3.3).

        Needs the boosters of all classes (a list trained here, or a model saved with them).
        """
        self._check_fitted()
        names = self.classes_.tolist()
        missing = [c for c in names if c not in self.boosters_]
        if missing:
            raise ValueError(f"no booster for {missing}: the other orders cannot be scored; retrain")
        if len(names) > MAX_BEST_CLASSES:
            raise ValueError(f"{len(names)} classes have too many orders to score")
        A = as_feature_matrix(X)
        truth_names = class_names(y, classes)
        truth = np.array([names.index(c) if c in names else -1 for c in truth_names.tolist()], dtype=np.intp)
        C = np.column_stack([self.boosters_[c].predict_proba(A)[:, 1] for c in names])
        scored = [
            (perm, self._accuracy(C, truth, perm)) for perm in itertools.permutations(range(len(names)))
        ]
        scored.sort(key=lambda ps: -ps[1])
        return [(tuple(names[k] for k in perm), acc) for perm, acc in scored]

    @property
    def n_features_in_(self) -> int:
        self._check_fitted()
        return self.boosters_[self.order_[0]].n_features_in_

    def with_order(self, order: Sequence[str]) -> DecisionList:
        """A copy consulting the boosters in another order (no retraining)."""
        self._check_fitted()
        new_order = tuple(str(c) for c in order)
        if sorted(new_order) != sorted(self.classes_.tolist()):
            raise ValueError(f"an order must list every class once: got {list(new_order)}")
        missing = [c for c in new_order[:-1] if c not in self.boosters_]
        if missing:
            raise ValueError(
                f"no booster for {missing}: this list was saved without them; retrain to reorder"
            )
        new = copy.copy(self)
        new.order = new_order
        new.order_ = new_order
        return new

    def reindexed(self, features: Sequence[int] | npt.NDArray[np.integer]) -> DecisionList:
        """A copy reading column ``i`` where this one read ``features[i]``.

        Keeps every booster whose features are all among ``features`` (at least the
        consulted ones must be; the default class's booster is dropped if it needs others).
        """
        self._check_fitted()
        cols = set(np.asarray(features).tolist())
        new = copy.copy(self)
        new.boosters_ = {
            c: b.reindexed(features)
            for c, b in self.boosters_.items()
            if c in self.order_[:-1] or set(b.used_features().tolist()) <= cols
        }
        return new

    # -- state for model files ----------------------------------------------------------

    def get_state(self) -> tuple[dict[str, Any], dict[str, npt.NDArray[Any]]]:
        """JSON-able metadata and named arrays (``b{i}.<name>`` for the i-th booster in order:
        the consulted ones first, then the default class's when it is kept)."""
        self._check_fitted()
        boosters = []
        arrays: dict[str, npt.NDArray[Any]] = {}
        for i, c in enumerate(c for c in self.order_ if c in self.boosters_):
            meta, arr = self.boosters_[c].get_state()
            boosters.append({"class": c, **meta})
            arrays.update({f"b{i}.{k}": v for k, v in arr.items()})
        meta_all = {
            "classes": self.classes_.tolist(),
            "order": list(self.order_),
            "order_name": order_name(self.order_),
            "order_mode": self.order_mode,
            "probabilistic": bool(self.probabilistic),
            "selection": getattr(self, "selection_", None),
            "order_scores": [[list(o), a] for o, a in getattr(self, "order_scores_", [])],
            "train_errors": dict(getattr(self, "train_errors_", {})),
            "boosters": boosters,
        }
        return meta_all, arrays

    @classmethod
    def from_state(cls, meta: Mapping[str, Any], arrays: Mapping[str, npt.NDArray[Any]]) -> DecisionList:
        """Rebuild a fitted list from :meth:`get_state`; ValueError says what is inconsistent."""
        classes = [str(c) for c in meta.get("classes", [])]
        order = tuple(str(c) for c in meta.get("order", []))
        if len(classes) < 2 or sorted(order) != sorted(classes):
            raise ValueError(f"the order {list(order)} must list every class of {classes} once")
        boosters_meta = list(meta.get("boosters", []))
        if [b.get("class") for b in boosters_meta] not in (list(order[:-1]), list(order)):
            raise ValueError(
                f"boosters {[b.get('class') for b in boosters_meta]} do not match the order {list(order)}"
            )
        mode = str(meta.get("order_mode", "explicit"))
        dl = cls(
            order=mode if mode in ("best", "heuristic") else order,
            probabilistic=bool(meta.get("probabilistic", True)),
        )
        dl.classes_ = np.asarray(classes, dtype=str)
        dl.order_ = order
        dl.boosters_ = {}
        for i, bmeta in enumerate(boosters_meta):
            prefix = f"b{i}."
            try:
                dl.boosters_[order[i]] = booster_from_state(
                    bmeta, {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix)}
                )
            except ValueError as exc:
                raise ValueError(f"booster {i} ({order[i]}): {exc}") from exc
        widths = {b.n_features_in_ for b in dl.boosters_.values()}
        if len(widths) != 1:
            raise ValueError(f"the boosters disagree on the number of features: {sorted(widths)}")
        dl.order_scores_ = [(tuple(o), float(a)) for o, a in meta.get("order_scores", [])]
        dl.train_errors_ = {str(k): float(v) for k, v in dict(meta.get("train_errors", {})).items()}
        if meta.get("selection") is not None:
            dl.selection_ = str(meta["selection"])
        return dl
