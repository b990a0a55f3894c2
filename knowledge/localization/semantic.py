"""The semantic observation of Monte Carlo localization (book Sect. 6.3, eq. 6.3).

The map is labelled: each free cell carries the class of its place (room, corridor,
doorway, ...), from the place classifier's whole-map labeling and relaxation (Sect. 4.5,
:func:`knowledge.topology.pipeline.build_topology`) or drawn by hand. The robot's
classifier labels the current scan ``z_t``. A particle at ``x_t`` whose cell has class ``y``
is weighted by ``Pr(z_t | y)``, "statistics about the output of the classifier given the
robot was at a place corresponding to y_t" — the classifier's confusion matrix, estimated
on scans with a known true class (:func:`confusion_matrix`). A particle off the labelled
cells (a wall, unknown space) gets ``1/K``, no information; the particle filter weights
those separately by the map's occupancy (the ``Pr(x_t | m)`` term of eq. 6.3).

:meth:`SemanticMap.class_likelihood` gives ``Pr(z_t | y)`` for every class at once, from the
histogram's most probable class or from the whole histogram (:data:`OBSERVATIONS`); the
particle filter weighs particles by it and, with its semantic proposal, draws new particles
in proportion to it (:mod:`~knowledge.localization.mcl`).

Arrays are in map orientation (row 0 at the bottom), as
:class:`~knowledge.localization.likelihood.LikelihoodField`'s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["OBSERVATIONS", "SemanticMap", "confusion_matrix"]

#: How the scan's class histogram ``h`` becomes the likelihood ``Pr(z_t | y)`` of each map
#: class ``y``: ``"argmax"`` the confusion matrix's column of the histogram's most probable
#: class (the book's eq. 6.3 with the classifier's label as ``z_t``); ``"histogram"`` the
#: mixture ``Σ_k h_k·P(z = k | y)`` over the whole histogram (the label is uncertain: a scan
#: the classifier finds 55 % room, 45 % corridor says little about either).
OBSERVATIONS = ("argmax", "histogram")


def confusion_matrix(
    true: Sequence[str], predicted: Sequence[str], classes: Sequence[str], *, smoothing: float = 1.0
) -> np.ndarray:
    """``(K, K)`` ``P(predicted = k | true = y)``, rows ``y``, columns ``k`` in ``classes``
    order, with ``smoothing`` added to every count (Laplace; a class never seen true gets a
    uniform row). Pairs with a class outside ``classes`` are left out."""
    if smoothing < 0:
        raise ValueError(f"smoothing must be >= 0, got {smoothing}")
    if len(true) != len(predicted):
        raise ValueError(f"true and predicted differ in length: {len(true)} and {len(predicted)}")
    index = {c: i for i, c in enumerate(classes)}
    k = len(classes)
    counts = np.full((k, k), float(smoothing))
    for t, p in zip(true, predicted, strict=True):
        if t in index and p in index:
            counts[index[t], index[p]] += 1.0
    rows = counts.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(rows > 0, counts / np.where(rows > 0, rows, 1.0), 1.0 / k)
    return out


@dataclass(frozen=True, eq=False)
class SemanticMap:
    """Per-cell place classes and the classifier's confusion matrix.

    Attributes:
        labels: ``(rows, cols)`` int8 class index per cell (-1: no class), map orientation,
            on the same cells as the localization map's likelihood field.
        classes: class names, the indices of ``labels`` and of both axes of ``confusion``.
        confusion: ``(K, K)`` ``P(z = k | y)`` (rows ``y``); every row sums to 1.
    """

    labels: np.ndarray
    classes: tuple[str, ...]
    confusion: np.ndarray

    def __post_init__(self) -> None:
        k = len(self.classes)
        c = np.asarray(self.confusion, dtype=np.float64)
        if c.shape != (k, k) or not np.all(c > 0) or not np.allclose(c.sum(axis=1), 1.0):
            raise ValueError(f"confusion must be ({k}, {k}) positive with rows summing to 1, got {c.shape}")
        lab = np.asarray(self.labels)
        if lab.ndim != 2 or lab.min(initial=-1) < -1 or lab.max(initial=-1) >= k:
            raise ValueError(f"labels must be 2-D class indices in [-1, {k}), got shape {lab.shape}")
        object.__setattr__(self, "labels", np.ascontiguousarray(lab, dtype=np.int8))
        object.__setattr__(self, "confusion", c)

    @classmethod
    def from_codes(
        cls,
        codes: npt.ArrayLike,
        legend: Mapping[int, str],
        classes: Sequence[str],
        confusion: npt.ArrayLike,
        *,
        image_orientation: bool = True,
    ) -> SemanticMap:
        """From a label image of codes (``legend``: code → class name; codes of other classes
        and 0 become -1), in image orientation (row 0 at the top) unless told otherwise."""
        img = np.asarray(codes)
        if image_orientation:
            img = img[::-1]
        index = {c: i for i, c in enumerate(classes)}
        labels = np.full(img.shape, -1, dtype=np.int8)
        for code, name in legend.items():
            if name in index:
                labels[img == code] = index[name]
        return cls(labels, tuple(classes), np.asarray(confusion, dtype=np.float64))

    def class_likelihood(self, proba: npt.ArrayLike, observation: str = "argmax") -> np.ndarray:
        """``(K + 1,)`` ``Pr(z_t | y)`` for each class ``y`` and, last, for a cell without class
        (``1/K``: no information), from the scan's histogram ``proba`` over :attr:`classes`
        (see :data:`OBSERVATIONS`)."""
        k = len(self.classes)
        h = np.asarray(proba, dtype=np.float64).reshape(-1)
        if h.shape != (k,) or not np.all(np.isfinite(h)) or h.min() < 0 or h.sum() <= 0:
            raise ValueError(f"proba must be {k} finite non-negative numbers, not all 0, got {h}")
        if observation == "argmax":
            col = self.confusion[:, int(np.argmax(h))]
        elif observation == "histogram":
            col = self.confusion @ (h / h.sum())
        else:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")
        return np.append(col, 1.0 / k)

    def classes_at(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``(N,)`` the class index of the cells ``(rows[i], cols[i])``, ``K`` for a cell without
        class or outside the map (the index of :meth:`class_likelihood`'s last entry)."""
        k = len(self.classes)
        R, C = self.labels.shape
        inside = (rows >= 0) & (rows < R) & (cols >= 0) & (cols < C)
        y = np.full(np.shape(rows), k, dtype=np.int64)
        lab = self.labels[rows[inside], cols[inside]].astype(np.int64)
        y[inside] = np.where(lab < 0, k, lab)
        return y

    def log_likelihood(self, rows: np.ndarray, cols: np.ndarray, observed: int) -> np.ndarray:
        """``(N,)`` ``log P(z = observed | y(cell))`` of the cells ``(rows[i], cols[i])``
        (outside the map or unlabelled: ``log 1/K``)."""
        k = len(self.classes)
        if not 0 <= observed < k:
            raise ValueError(f"observed must be a class index in [0, {k}), got {observed}")
        R, C = self.labels.shape
        inside = (rows >= 0) & (rows < R) & (cols >= 0) & (cols < C)
        y = np.full(rows.shape, -1, dtype=np.int64)
        y[inside] = self.labels[rows[inside], cols[inside]]
        table = np.append(np.log(self.confusion[:, observed]), np.log(1.0 / k))
        return table[y]  # index -1 is the appended "no class" entry
