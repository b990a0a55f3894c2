"""The hidden Markov model of Sect. 5.4: place labels filtered along the robot's trajectory.

The belief over the place classes ``y_t`` is updated at every classified scan (eq. 5.3)::

    bel(y_t) = η · Pr(z_t | y_t) · Σ_{y_{t−1}} Pr(y_t | y_{t−1}, u_{t−1}) · bel(y_{t−1})

* the observation ``z_t`` is the probabilistic decision list's histogram (eq. 4.5), and its
  likelihood given a class is ``exp(−KL(z_t ‖ ẑ(y)))`` (eq. 5.4), with ``ẑ(y)`` the mean
  histogram of observations made in places of class ``y`` (the book averages ``m = 50``);
* the action ``u ∈ {Move, Stay}``; the Move transitions are counted over simulated moves of
  20–50 cm from random poses in labelled maps (the book runs 1,000), Stay keeps the class;
* the belief starts uniform.

Beyond the book, the observation model can be the histogram itself (``observation =
"histogram"``): ``Pr(z_t | y) ∝ (p_t(y) + eps)^γ``, the classifier's own posterior taken as the
likelihood (its training weights are class-balanced, so its prior is flat), tempered by
``γ`` because consecutive scans of a moving robot are far from independent. On the real
Freiburg 079 scans eq. 5.4 gains 1.3 points over the raw labels and this 3.9
(``docs/results/places_fr079.md``, the agent model trained without that log): the mean histogram of doorway observations is a blend of
the others, so eq. 5.4 lets ambiguous room scans pass as doorways.

:class:`PlaceHMM` follows the estimator manners of the boosters: ``__init__`` stores the
parameters, :meth:`PlaceHMM.fit` returns ``self``, fitted state ends in ``_``, and using an
unfitted model raises :class:`~knowledge.errors.NotFittedError`. :meth:`PlaceHMM.filter`
runs a whole sequence; :class:`HMMFilter` is the per-scan form the agent uses (it decides
Move or Stay from the distance driven since the last Move). The fitted arrays go into the
place model file (:meth:`PlaceHMM.to_arrays`, :meth:`PlaceHMM.from_arrays`; no pickle).

KL divergence needs care where a bin is 0: both histograms are mixed with ``eps`` of the
uniform histogram first (``eps`` = 10⁻³), which bounds every likelihood away from 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Self

import numpy as np
import numpy.typing as npt

from knowledge.errors import NotFittedError

__all__ = ["OBSERVATIONS", "HMMFilter", "PlaceHMM", "kl_likelihood", "move_transitions"]

#: Observation models: eq. 5.4, or the classifier's histogram (tempered).
OBSERVATIONS = ("kl", "histogram")

FloatArray = npt.NDArray[np.float64]


def _smooth(p: npt.ArrayLike, eps: float) -> FloatArray:
    a = np.asarray(p, dtype=np.float64)
    a = np.clip(a, 0.0, None)
    s = a.sum(axis=-1, keepdims=True)
    a = np.where(s > 0, a / np.where(s > 0, s, 1.0), 1.0 / a.shape[-1])
    return (1.0 - eps) * a + eps / a.shape[-1]


def kl_likelihood(z: npt.ArrayLike, means: npt.ArrayLike, eps: float = 1e-3) -> FloatArray:
    """Eq. 5.4: ``exp(−KL(z ‖ ẑ(y)))`` for histograms ``z`` ``(..., K)`` against the class
    means ``(K, K)`` (row y is ``ẑ(y)``); returns ``(..., K)``, one likelihood per class."""
    zs = _smooth(z, eps)
    ms = _smooth(means, eps)
    kl = np.einsum("...k,...k->...", zs, np.log(zs))[..., None] - zs @ np.log(ms).T
    return np.exp(-np.maximum(kl, 0.0))


def move_transitions(
    labels: Sequence[npt.NDArray[Any]],
    resolutions: Sequence[float],
    free: Sequence[npt.NDArray[np.bool_]],
    codes: Sequence[int],
    rng: np.random.Generator,
    *,
    n_moves: int = 1000,
    distance: tuple[float, float] = (0.2, 0.5),
    max_tries: int = 100,
) -> npt.NDArray[np.int64]:
    """Counts ``(K, K)`` of class changes over simulated moves (Sect. 5.4).

    Each move starts at a random labelled free cell of a random map (maps drawn in proportion
    to their labelled area) with a random heading and goes ``distance`` metres (uniform)
    straight ahead; a move whose straight line leaves the free cells is drawn again. Row i,
    column j counts moves from class ``codes[i]`` to ``codes[j]``; moves from or to cells of
    other codes are drawn again.

    Args:
        labels: per map, ``(rows, cols)`` class codes.
        resolutions: per map, metres per cell.
        free: per map, ``(rows, cols)`` bool free cells.
        codes: the class codes, in the model's class order.
        rng: the random generator.
        n_moves: moves to count.
        distance: (min, max) metres of a move.
        max_tries: draws per move before giving up (a map with no room to move).
    """
    if not labels:
        raise ValueError("move_transitions needs at least one labelled map")
    lut = np.full(256, -1, dtype=np.int64)
    lut[np.asarray(codes, dtype=np.int64)] = np.arange(len(codes))
    starts = [np.argwhere(f & (lut[lab] >= 0)) for lab, f in zip(labels, free, strict=True)]
    area = np.array([len(s) * r * r for s, r in zip(starts, resolutions, strict=True)], dtype=np.float64)
    if area.sum() == 0:
        raise ValueError("no labelled free cell of the given classes to start a move from")
    counts = np.zeros((len(codes), len(codes)), dtype=np.int64)
    for _ in range(n_moves):
        for _try in range(max_tries):
            k = int(rng.choice(len(labels), p=area / area.sum()))
            lab, f, res, st = labels[k], free[k], resolutions[k], starts[k]
            r0, c0 = st[rng.integers(len(st))]
            th = rng.uniform(-math.pi, math.pi)
            d = rng.uniform(*distance) / res
            n = max(2, math.ceil(d * 2))
            t = np.linspace(0.0, d, n)
            rr = np.floor(r0 + 0.5 - t * math.sin(th)).astype(np.int64)  # rows grow downwards
            cc = np.floor(c0 + 0.5 + t * math.cos(th)).astype(np.int64)
            if rr.min() < 0 or cc.min() < 0 or rr.max() >= f.shape[0] or cc.max() >= f.shape[1]:
                continue
            if not f[rr, cc].all():
                continue
            a, b = lut[lab[r0, c0]], lut[lab[rr[-1], cc[-1]]]
            if a < 0 or b < 0:
                continue
            counts[a, b] += 1
            break
    return counts


class PlaceHMM:
    """The HMM of Sect. 5.4 over a place model's classes (see the module doc).

    Args:
        m: observations averaged per class for ``ẑ(y)`` (the book: 50); None averages all.
        n_moves: simulated moves for the Move transitions (the book: 1,000).
        distance: (min, max) metres of a simulated move (the book: 20–50 cm).
        stay: probability of keeping the class under Stay (the book: the class is kept).
        prior: Laplace pseudo-count added to every Move transition count.
        eps: share of the uniform histogram mixed into histograms before the KL divergence.
        move_min: metres driven that make the next update a Move (the agent's filter).
        observation: "kl" (eq. 5.4) or "histogram" (the histogram, tempered; see the module doc).
        temper: γ of the "histogram" observation model.

    Fitted attributes: ``classes_`` ``(K,)``, ``means_`` ``(K, K)`` (row y: ``ẑ(y)``),
    ``move_`` ``(K, K)`` and ``stay_`` ``(K, K)`` row-stochastic transition matrices
    ``Pr(y_t = j | y_{t−1} = i, u)``, ``move_counts_`` ``(K, K)``, ``n_observations_`` ``(K,)``.
    """

    def __init__(
        self,
        *,
        m: int | None = 50,
        n_moves: int = 1000,
        distance: tuple[float, float] = (0.2, 0.5),
        stay: float = 1.0,
        prior: float = 1.0,
        eps: float = 1e-3,
        move_min: float = 0.2,
        observation: str = "kl",
        temper: float = 0.5,
    ) -> None:
        self.m = m
        self.n_moves = n_moves
        self.distance = distance
        self.stay = stay
        self.prior = prior
        self.eps = eps
        self.move_min = move_min
        self.observation = observation
        self.temper = temper

    def get_params(self) -> dict[str, Any]:
        return {
            "m": self.m,
            "n_moves": self.n_moves,
            "distance": list(self.distance),
            "stay": self.stay,
            "prior": self.prior,
            "eps": self.eps,
            "move_min": self.move_min,
            "observation": self.observation,
            "temper": self.temper,
        }

    def _check_params(self) -> None:
        if self.m is not None and self.m < 1:
            raise ValueError(f"m must be a number of observations >= 1 or None, got {self.m!r}")
        if not 0.0 < self.stay <= 1.0:
            raise ValueError(f"stay must be a probability in (0, 1], got {self.stay!r}")
        if not (0.0 <= self.eps < 1.0 and self.prior >= 0 and self.move_min >= 0):
            raise ValueError("eps must be in [0, 1), prior and move_min >= 0")
        if self.observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {self.observation!r}")
        if not (math.isfinite(self.temper) and self.temper > 0):
            raise ValueError(f"temper must be a positive exponent, got {self.temper!r}")

    def fit(
        self,
        histograms: npt.ArrayLike,
        y: npt.ArrayLike,
        *,
        classes: Sequence[str],
        move_counts: npt.ArrayLike,
        rng: np.random.Generator | None = None,
    ) -> Self:
        """Learn ``ẑ(y)`` from histograms ``(N, K)`` (columns in ``classes`` order) of
        observations made in places of class ``y`` ``(N,)`` (names), and the Move matrix from
        ``move_counts`` ``(K, K)`` (:func:`move_transitions`). ``rng`` draws the ``m``
        observations per class (default: a generator seeded with 0)."""
        self._check_params()
        H = np.asarray(histograms, dtype=np.float64)
        names = np.asarray(y).astype(str)
        K = len(classes)
        if H.ndim != 2 or H.shape[1] != K or names.shape != (H.shape[0],):
            raise ValueError(f"histograms must be (N, {K}) with N labels, got {H.shape} and {names.shape}")
        counts = np.asarray(move_counts, dtype=np.float64)
        if counts.shape != (K, K) or (counts < 0).any():
            raise ValueError(f"move_counts must be a (K, K) = ({K}, {K}) array of counts >= 0")
        gen = rng if rng is not None else np.random.default_rng(0)
        means = np.empty((K, K))
        n_obs = np.zeros(K, dtype=np.int64)
        for i, c in enumerate(classes):
            rows = np.flatnonzero(names == c)
            if rows.size == 0 and self.observation == "histogram":
                means[i] = 1.0 / K  # not used by this observation model
                continue
            if rows.size == 0:
                raise ValueError(f"no observation of class {c!r} to learn its mean histogram from")
            if self.m is not None and rows.size > self.m:
                rows = gen.choice(rows, self.m, replace=False)
            means[i] = H[rows].mean(axis=0)
            n_obs[i] = rows.size
        move = counts + self.prior
        move /= move.sum(axis=1, keepdims=True)
        stay = np.full((K, K), (1.0 - self.stay) / max(K - 1, 1))
        np.fill_diagonal(stay, self.stay if K > 1 else 1.0)
        self.classes_ = np.asarray(list(classes), dtype=str)
        self.means_ = means / means.sum(axis=1, keepdims=True)
        self.move_ = move
        self.stay_ = stay
        self.move_counts_ = counts.astype(np.int64)
        self.n_observations_ = n_obs
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "means_"):
            raise NotFittedError(
                "this PlaceHMM is not fitted yet: call fit(...) first (or load a place model)"
            )

    @property
    def prior_(self) -> FloatArray:
        """The uniform initial belief ``(K,)``."""
        self._check_fitted()
        return np.full(len(self.classes_), 1.0 / len(self.classes_))

    def likelihood(self, histograms: npt.ArrayLike) -> FloatArray:
        """``Pr(z | y)`` for histograms ``(..., K)``: ``(..., K)`` (eq. 5.4, or the tempered
        histogram; up to a factor that does not depend on the class)."""
        self._check_fitted()
        if self.observation == "histogram":
            return np.asarray(_smooth(histograms, self.eps) ** self.temper)
        return kl_likelihood(histograms, self.means_, self.eps)

    def step(self, belief: npt.ArrayLike, histogram: npt.ArrayLike, moved: bool) -> FloatArray:
        """One update of eq. 5.3: the belief ``(K,)`` after the action (Move if ``moved``)
        and the observation ``histogram`` ``(K,)``."""
        self._check_fitted()
        T = self.move_ if moved else self.stay_
        predicted = np.asarray(belief, dtype=np.float64) @ T
        post = predicted * self.likelihood(histogram)
        s = post.sum()
        return post / s if s > 0 else self.prior_

    def filter(self, histograms: npt.ArrayLike, moved: npt.ArrayLike) -> FloatArray:
        """Beliefs ``(T, K)`` after each of the observations ``(T, K)``; ``moved`` ``(T,)``
        says whether the action before observation t was Move (the first is ignored: the
        belief starts uniform)."""
        self._check_fitted()
        H = np.asarray(histograms, dtype=np.float64)
        mv = np.asarray(moved, dtype=bool)
        if H.ndim != 2 or H.shape[1] != len(self.classes_) or mv.shape != (H.shape[0],):
            raise ValueError(
                f"histograms must be (T, {len(self.classes_)}) and moved (T,), got {H.shape}, {mv.shape}"
            )
        L = self.likelihood(H)
        out = np.empty_like(L)
        bel = self.prior_
        for t in range(H.shape[0]):
            pred = bel if t == 0 else bel @ (self.move_ if mv[t] else self.stay_)
            post = pred * L[t]
            s = post.sum()
            bel = post / s if s > 0 else self.prior_
            out[t] = bel
        return out

    # -- model files ---------------------------------------------------------------------

    def to_arrays(self) -> tuple[dict[str, Any], dict[str, npt.NDArray[Any]]]:
        """JSON-able metadata and named arrays for a model file."""
        self._check_fitted()
        meta = {"params": self.get_params(), "classes": self.classes_.tolist()}
        arrays = {
            "means": self.means_,
            "move": self.move_,
            "stay": self.stay_,
            "move_counts": self.move_counts_,
            "n_observations": self.n_observations_,
        }
        return meta, arrays

    @classmethod
    def from_arrays(cls, meta: Mapping[str, Any], arrays: Mapping[str, npt.NDArray[Any]]) -> PlaceHMM:
        """Rebuild a fitted HMM from :meth:`to_arrays`; ValueError says what is inconsistent."""
        params = dict(meta.get("params") or {})
        if "distance" in params:
            params["distance"] = tuple(params["distance"])
        hmm = cls(**params)
        hmm._check_params()  # a stored parameter out of range (a misspelt observation) is refused
        classes = [str(c) for c in meta.get("classes", [])]
        K = len(classes)
        for name in ("means", "move", "stay"):
            a = np.asarray(arrays.get(name, np.empty(0)), dtype=np.float64)
            if a.shape != (K, K) or not np.isfinite(a).all() or (a < 0).any():
                raise ValueError(f"the HMM's {name!r} must be a ({K}, {K}) array of probabilities")
            if not np.allclose(a.sum(axis=1), 1.0, atol=1e-6):
                raise ValueError(f"the HMM's {name!r} rows must sum to 1")
        hmm.classes_ = np.asarray(classes, dtype=str)
        hmm.means_ = np.asarray(arrays["means"], dtype=np.float64)
        hmm.move_ = np.asarray(arrays["move"], dtype=np.float64)
        hmm.stay_ = np.asarray(arrays["stay"], dtype=np.float64)
        hmm.move_counts_ = np.asarray(arrays.get("move_counts", np.zeros((K, K))), dtype=np.int64)
        hmm.n_observations_ = np.asarray(arrays.get("n_observations", np.zeros(K)), dtype=np.int64)
        return hmm


class HMMFilter:
    """The per-scan HMM filter of the agent: the belief, and the distance since the last Move.

    ``update(histogram, pose)`` is a Move update when the robot has driven ``move_min``
    metres since the last Move (straight-line distance from that pose), else a Stay update.
    """

    def __init__(self, hmm: PlaceHMM) -> None:
        hmm._check_fitted()
        self.hmm = hmm
        self.reset()

    def reset(self) -> None:
        """Forget the belief (uniform again) and the last Move's pose."""
        self.belief = self.hmm.prior_
        self._anchor: tuple[float, float] | None = None

    def update(self, histogram: npt.ArrayLike, xy: tuple[float, float]) -> FloatArray:
        """The belief ``(K,)`` after this scan's histogram, taken at position ``xy`` (metres)."""
        moved = False
        if self._anchor is None:
            self._anchor = (float(xy[0]), float(xy[1]))
        elif math.hypot(xy[0] - self._anchor[0], xy[1] - self._anchor[1]) >= self.hmm.move_min:
            moved = True
            self._anchor = (float(xy[0]), float(xy[1]))
        self.belief = self.hmm.step(self.belief, histogram, moved)
        return self.belief
