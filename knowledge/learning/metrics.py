"""Classification scores: accuracy, balanced accuracy, confusion matrices, printed tables."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Scores:
    """Scores of predictions against the truth over a fixed list of classes.

    Attributes:
        classes: class names; rows/columns of ``confusion`` follow this order.
        confusion: ``(K, K)`` int64, ``confusion[i, j]`` = examples of true class i predicted as j.
        accuracy: fraction of examples predicted correctly.
        balanced_accuracy: mean over classes (present in the truth) of the per-class recall.
        recall: ``(K,)`` per-class recall (NaN for a class absent from the truth).
        precision: ``(K,)`` per-class precision (NaN for a class never predicted).
        n: number of examples scored.
    """

    classes: tuple[str, ...]
    confusion: np.ndarray
    accuracy: float
    balanced_accuracy: float
    recall: np.ndarray
    precision: np.ndarray
    n: int

    def as_dict(self) -> dict[str, object]:
        """JSON-ready view."""

        def clean(v: float) -> float | None:
            return None if not np.isfinite(v) else round(float(v), 6)

        return {
            "n": self.n,
            "accuracy": clean(self.accuracy),
            "balanced_accuracy": clean(self.balanced_accuracy),
            "classes": list(self.classes),
            "confusion": self.confusion.tolist(),
            "recall": {c: clean(r) for c, r in zip(self.classes, self.recall, strict=True)},
            "precision": {c: clean(p) for c, p in zip(self.classes, self.precision, strict=True)},
        }


def score(y_true: np.ndarray, y_pred: np.ndarray, classes: Sequence[str]) -> Scores:
    """Scores of ``y_pred`` against ``y_true`` (arrays of class names).

    Examples whose true class is not in ``classes`` are ignored (e.g. doorway cells for a
    room/corridor score); a prediction outside ``classes`` counts as wrong.
    """
    yt = np.asarray(y_true)
    yp = np.asarray(y_pred)
    if yt.shape != yp.shape:
        raise ValueError(f"y_true {yt.shape} and y_pred {yp.shape} differ in shape")
    cls = tuple(classes)
    index = {c: i for i, c in enumerate(cls)}
    keep = np.isin(yt, cls)
    ti = np.array([index[c] for c in yt[keep]], dtype=np.int64)
    pi = np.array([index.get(c, -1) for c in yp[keep]], dtype=np.int64)
    k = len(cls)
    conf = np.zeros((k, k), dtype=np.int64)
    ok = pi >= 0
    np.add.at(conf, (ti[ok], pi[ok]), 1)
    n = int(keep.sum())
    correct = int(np.trace(conf))
    support = np.bincount(ti, minlength=k).astype(np.float64)
    predicted = conf.sum(axis=0).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        recall = np.where(support > 0, np.diag(conf) / support, np.nan)
        precision = np.where(predicted > 0, np.diag(conf) / predicted, np.nan)
    present = support > 0
    return Scores(
        classes=cls,
        confusion=conf,
        accuracy=correct / n if n else float("nan"),
        balanced_accuracy=float(np.mean(recall[present])) if present.any() else float("nan"),
        recall=recall,
        precision=precision,
        n=n,
    )


def format_confusion(s: Scores) -> str:
    """The confusion matrix as a readable text table (rows: truth, columns: prediction)."""
    width = max(8, *(len(c) for c in s.classes)) + 1
    head = "true \\ predicted".ljust(width + 8) + "".join(c.rjust(width) for c in s.classes) + "   recall"
    lines = [head]
    for i, c in enumerate(s.classes):
        row = "".join(str(int(v)).rjust(width) for v in s.confusion[i])
        rec = "" if not np.isfinite(s.recall[i]) else f"{100 * s.recall[i]:8.2f}%"
        lines.append(c.ljust(width + 8) + row + rec)
    return "\n".join(lines)
