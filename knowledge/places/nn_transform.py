"""The nearest-neighbour feature transform of instance-based AMNs (Sect. 4.6.2, eq. 4.10–4.11).

A feature vector x̃ ∈ R^L becomes the distances to its M nearest training instances of each
of the K classes, τ_M(x̃) ∈ R^{K·M} (eq. 4.11; M = 1 is eq. 4.10), ordered class by class and,
within a class, nearest first. The AMN that reads these is linear in them, which separates
classes a nearest-neighbour rule separates (Fig. 4.5).

Distances are Euclidean in *standardised* feature space (each column minus its training
mean, divided by its training standard deviation; a constant column gets scale 1): scan
features mix metres, square metres and ratios, and unscaled, the largest would decide every
neighbour. One :class:`scipy.spatial.cKDTree` per class holds that class's instances.

On the training examples themselves (:meth:`NNTransform.transform_training`), each example's
own instance is left out, otherwise its distance to its own class would always be 0 and the
learner would trust that column far more than it deserves on new data.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from knowledge.errors import NotFittedError

FloatArray = npt.NDArray[np.float64]


class NNTransform:
    """τ_M of eq. 4.11, estimator style: ``fit(X, y)`` stores the instances, ``transform(X)`` maps.

    Args:
        n_neighbors: M, distances kept per class.

    Fitted attributes: ``classes_`` (K,), ``mean_`` and ``scale_`` (L,), ``X_`` (N, L) the
    standardised instances, ``y_`` (N,) their class indices into ``classes_``.
    """

    def __init__(self, n_neighbors: int = 1) -> None:
        self.n_neighbors = n_neighbors

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> NNTransform:
        A = np.asarray(X, dtype=np.float64)
        labels = np.asarray(y)
        if A.ndim != 2 or labels.shape != (A.shape[0],):
            raise ValueError(f"X must be (N, L) and y (N,), got {A.shape} and {labels.shape}")
        if self.n_neighbors < 1:
            raise ValueError(f"n_neighbors must be >= 1, got {self.n_neighbors}")
        classes, yi = np.unique(labels, return_inverse=True)
        counts = np.bincount(yi, minlength=len(classes))
        if counts.min() < self.n_neighbors + 1:
            raise ValueError(
                f"every class needs more than n_neighbors={self.n_neighbors} instances; "
                f"got {dict(zip(classes.tolist(), counts.tolist(), strict=True))}"
            )
        mean = A.mean(axis=0)
        std = A.std(axis=0)
        scale = np.where(std > 0, std, 1.0)
        return self.set_state(classes, mean, scale, (A - mean) / scale, yi)

    def set_state(
        self,
        classes: npt.ArrayLike,
        mean: npt.ArrayLike,
        scale: npt.ArrayLike,
        X_std: npt.ArrayLike,
        y_index: npt.ArrayLike,
    ) -> NNTransform:
        """Restore a fitted transform from its arrays (as stored in a model file)."""
        self.classes_ = np.asarray(classes)
        self.mean_ = np.asarray(mean, dtype=np.float64)
        self.scale_ = np.asarray(scale, dtype=np.float64)
        self.X_ = np.asarray(X_std, dtype=np.float64)
        self.y_ = np.asarray(y_index, dtype=np.intp)
        self.trees_ = [cKDTree(self.X_[self.y_ == k]) for k in range(len(self.classes_))]
        return self

    @property
    def n_outputs(self) -> int:
        """K·M, the width of the transformed features."""
        self._check()
        return len(self.classes_) * self.n_neighbors

    def _check(self) -> None:
        if not hasattr(self, "trees_"):
            raise NotFittedError("NNTransform is not fitted: call fit(X, y) first")

    def _standardise(self, X: npt.ArrayLike) -> FloatArray:
        self._check()
        A = np.asarray(X, dtype=np.float64)
        if A.ndim != 2 or A.shape[1] != self.X_.shape[1]:
            raise ValueError(f"expected (S, {self.X_.shape[1]}) features, got {A.shape}")
        return (A - self.mean_) / self.scale_

    def transform(self, X: npt.ArrayLike) -> FloatArray:
        """``(S, K·M)`` distances (eq. 4.11) of the rows of ``X`` ``(S, L)``."""
        Z = self._standardise(X)
        M = self.n_neighbors
        out = np.empty((len(Z), len(self.trees_) * M))
        for k, tree in enumerate(self.trees_):
            d, _ = tree.query(Z, k=M)
            out[:, k * M : (k + 1) * M] = np.reshape(d, (len(Z), M))
        return out

    def transform_training(self) -> FloatArray:
        """τ_M of the fitted instances, each one's own instance left out (leave-one-out)."""
        Z = self.X_
        M = self.n_neighbors
        out = np.empty((len(Z), len(self.trees_) * M))
        for k, tree in enumerate(self.trees_):
            own = self.y_ == k
            d, _ = tree.query(Z[~own], k=M)
            out[~own, k * M : (k + 1) * M] = np.reshape(d, (-1, M))
            # the instance itself is at distance 0 among its own class: ask for one more, drop it
            d, _ = tree.query(Z[own], k=M + 1)
            out[own, k * M : (k + 1) * M] = np.reshape(d, (-1, M + 1))[:, 1:]
        return out
