"""The boosted leg detector (book Sect. 8.3): generalized AdaBoost over the App. C features.

:class:`LegDetector` classifies every segment of a scan with at least ``min_points`` points
as *person* (a leg, or both legs seen as one segment) or *non-person*, from the features it
was trained on (by default the shape features C.1–C.3 and C.6–C.13: not C.14, which needs
consecutive scans, nor the jump distances C.4/C.5, see :data:`~knowledge.people.features.DEFAULT_COLUMNS`), with
``T = 100`` threshold weak learners (eq. 8.1) boosted by the generalized AdaBoost of Sect. 4.2
(:class:`~knowledge.learning.boosting.GeneralizedAdaBoost`). A segment is a person when
``F(x) ≥ threshold`` (0 by default, the sign of the strong classifier); every beam of a person
segment is labelled person, all other beams non-person. A detector may have a ``max_range``:
segments whose centroid is farther from the sensor are never persons (the bundled model's
training data has people only up to 5 m, so it does not claim any beyond).

It follows the estimator manners of the places boosters: ``__init__`` stores parameters,
:meth:`LegDetector.fit` returns ``self``, an unfitted detector raises NotFittedError.

File format ``loci.people-model/2`` (``/1`` models measured C.4/C.5 across no-return beams
and are refused): one ``.npz`` holding a JSON header as a uint8 array
``header_json`` and the booster's arrays as ``booster.<name>``; written atomically and read
with ``allow_pickle=False``; every problem on loading is a :class:`ModelError`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any, Self

import numpy as np
import numpy.typing as npt

from knowledge.errors import ModelError, NotFittedError
from knowledge.learning.boosting import STATE_ARRAYS, GeneralizedAdaBoost, booster_from_state
from knowledge.npzfile import read_npz, write_npz
from knowledge.people.features import (
    DEFAULT_COLUMNS,
    FEATURE_CODES,
    FEATURES,
    N_FEATURES,
    _features,
    feature_label,
)
from knowledge.people.segmentation import DEFAULT_JUMP, FloatArray, Segmentation, segment_scan

FORMAT = "loci.people-model/2"
FORMAT_FAMILY = "loci.people-model/"
BOOSTER_PREFIX = "booster."
#: The detector shipped with genius-loci (see docs/people.md for the command that made it).
DEFAULT_MODEL = Path(__file__).resolve().parent / "models" / "legs_default.npz"


def genius_loci_version() -> str:
    try:
        return metadata.version("genius-loci")
    except metadata.PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True, eq=False)
class SegmentDetection:
    """The detector's view of one scan.

    Attributes:
        segmentation: the scan's segments.
        features: ``(S, 14)`` float64 features C.1–C.14 (C.14 is 0 without a previous scan).
        score: ``(S,)`` float64 strong-classifier output ``F``; −inf for segments the detector
            does not classify (fewer than ``min_points`` points, or beyond ``max_range``).
        is_person: ``(S,)`` bool, the segment is classified person.
        centroids: ``(S, 2)`` centres of gravity of the segments, metres, sensor frame (None:
            computed from the segmentation when asked).
    """

    segmentation: Segmentation
    features: FloatArray
    score: FloatArray
    is_person: npt.NDArray[np.bool_]
    centroids: FloatArray | None = None

    @property
    def beam_labels(self) -> npt.NDArray[np.bool_]:
        """``(B,)`` bool per-beam labels: True = person, False = non-person (or no return)."""
        return self.segmentation.beam_mask(self.is_person)

    @property
    def legs(self) -> FloatArray:
        """``(K, 2)`` centroids of the person segments in metres, sensor frame."""
        centre = self.centroids if self.centroids is not None else self.segmentation.centroids()
        return centre[self.is_person]

    @property
    def leg_scores(self) -> FloatArray:
        """``(K,)`` ``F`` of the person segments, in the order of :attr:`legs`."""
        return self.score[self.is_person]


class LegDetector:
    """Segment classifier person / non-person (see the module doc).

    Parameters: ``n_rounds`` (T), ``columns`` (feature columns used, indices into
    :data:`~knowledge.people.features.FEATURES`), ``jump`` and ``max_gap`` (segmentation),
    ``min_points`` (smaller segments are never persons), ``max_range`` (metres or None;
    segments whose centroid is farther are never persons), ``threshold`` on ``F``.

    Fitted: ``booster_`` (a :class:`GeneralizedAdaBoost` over the ``columns``), and
    ``training_`` (a JSON-able summary that is saved with the model).
    """

    def __init__(
        self,
        n_rounds: int = 100,
        *,
        columns: Sequence[int] = DEFAULT_COLUMNS,
        jump: float = DEFAULT_JUMP,
        max_gap: int | None = None,
        min_points: int = 2,
        max_range: float | None = None,
        threshold: float = 0.0,
    ) -> None:
        self.n_rounds = n_rounds
        self.columns = tuple(int(c) for c in columns)
        self.jump = jump
        self.max_gap = max_gap
        self.min_points = min_points
        self.max_range = max_range
        self.threshold = threshold

    def _check_params(self) -> None:
        if not self.columns or len(set(self.columns)) != len(self.columns):
            raise ValueError(f"columns must be distinct feature columns, got {self.columns}")
        bad = [c for c in self.columns if not 0 <= c < N_FEATURES]
        if bad:
            raise ValueError(f"feature columns must be in 0..{N_FEATURES - 1} (C.1..C.14), got {bad}")
        if int(self.min_points) != self.min_points or self.min_points < 1:
            raise ValueError(f"min_points must be an integer >= 1, got {self.min_points!r}")
        if self.max_range is not None and not (math.isfinite(self.max_range) and self.max_range > 0):
            raise ValueError(f"max_range must be None or a positive number of metres, got {self.max_range!r}")
        if not math.isfinite(self.threshold):
            raise ValueError(f"threshold must be finite, got {self.threshold!r}")

    @property
    def uses_motion(self) -> bool:
        """True if C.14 (which needs the previous scan) is among the columns."""
        return 13 in self.columns

    def __repr__(self) -> str:
        codes = ",".join(FEATURE_CODES[c] for c in self.columns)
        return (
            f"LegDetector(n_rounds={self.n_rounds}, columns=[{codes}], jump={self.jump}, "
            f"max_range={self.max_range}, threshold={self.threshold})"
        )

    # -- training / prediction -----------------------------------------------------------

    def fit(
        self,
        X: npt.ArrayLike,
        y: npt.ArrayLike,
        *,
        training: Mapping[str, Any] | None = None,
        sample_weight: npt.ArrayLike | None = None,
    ) -> Self:
        """Learn from features ``X`` ``(n, 14)`` (all of C.1–C.14) and labels ``y`` ``(n,)`` (True = person).

        ``training`` is a JSON-able summary of the data, saved with the model.
        ``sample_weight`` ``(n,)`` scales the booster's initial weights within each class.
        """
        self._check_params()
        A = self._select(X)
        self.booster_ = GeneralizedAdaBoost(n_rounds=self.n_rounds, weak="threshold").fit(
            A, y, sample_weight=sample_weight
        )
        self.training_ = dict(training or {})
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "booster_"):
            raise NotFittedError("this LegDetector is not fitted: call fit(X, y) or LegDetector.load(path)")

    def _select(self, X: npt.ArrayLike) -> FloatArray:
        A = np.asarray(X, dtype=np.float64)
        if A.ndim != 2 or A.shape[1] != N_FEATURES:
            raise ValueError(
                f"X must be (n, {N_FEATURES}) features C.1–C.14 (knowledge.people.features), got shape {A.shape}"
            )
        return A[:, list(self.columns)]

    def decision_function(self, X: npt.ArrayLike) -> FloatArray:
        """``F(x)`` ``(n,)`` of features ``(n, 14)``; ``F ≥ threshold`` means person."""
        self._check_fitted()
        A = self._select(X)
        if A.shape[0] == 0:
            return np.zeros(0)
        return self.booster_.decision_function(A)

    def predict(self, X: npt.ArrayLike, distance: npt.ArrayLike | None = None) -> npt.NDArray[np.bool_]:
        """``(n,)`` bool, True = person, for features ``(n, 14)``.

        ``distance`` ``(n,)``: the segments' centroid distances in metres; with it, segments
        beyond ``max_range`` are non-persons, as in :meth:`detect`. Segments with fewer than
        ``min_points`` points (C.1) are non-persons.
        """
        A = np.asarray(X, dtype=np.float64)
        out = self.decision_function(A) >= self.threshold
        if A.shape[0]:
            out &= self.classifies(A[:, 0], distance)
        return np.asarray(out)

    def classifies(
        self, n_points: npt.ArrayLike, distance: npt.ArrayLike | None = None
    ) -> npt.NDArray[np.bool_]:
        """``(n,)`` bool: segments of ``n_points`` points at ``distance`` metres (if given) that this
        detector classifies at all; the others are non-persons."""
        ok = np.asarray(n_points) >= self.min_points
        if distance is not None and self.max_range is not None:
            ok = ok & (np.asarray(distance, dtype=np.float64) <= self.max_range)
        return np.asarray(ok)

    def detect(
        self,
        ranges: npt.ArrayLike,
        angle_min: float,
        angle_increment: float,
        *,
        range_max: float,
        range_min: float = 0.0,
        previous: npt.ArrayLike | None = None,
        dt: float | None = None,
    ) -> SegmentDetection:
        """Segment one scan ``(B,)`` (metres), compute the features and classify every segment.

        ``range_max``/``range_min``: the sensor's range limits in metres (readings outside are
        no returns). ``previous``/``dt``: the previous scan of the same sensor and the seconds
        since, for C.14.
        """
        self._check_fitted()
        seg = segment_scan(
            ranges,
            angle_min,
            angle_increment,
            range_max=range_max,
            range_min=range_min,
            jump=self.jump,
            max_gap=self.max_gap,
        )
        X, centre = _features(seg, range_max=range_max, range_min=range_min, previous=previous, dt=dt)
        S = X.shape[0]
        score = np.full(S, -np.inf)
        big = self.classifies(X[:, 0], np.hypot(centre[:, 0], centre[:, 1]) if S else None)
        rows = np.flatnonzero(big)
        if rows.size:
            score[rows] = self.booster_.decision_function(X[rows[:, None], list(self.columns)])
        return SegmentDetection(seg, X, score, score >= self.threshold, centre)

    # -- inspection ----------------------------------------------------------------------

    def feature_importance(self) -> FloatArray:
        """``(14,)`` sum of α over the weak learners of each feature (0 for unused ones)."""
        self._check_fitted()
        out = np.zeros(N_FEATURES)
        out[list(self.columns)] = self.booster_.feature_importance()
        return out

    def top_features(self, k: int = 5) -> list[dict[str, Any]]:
        """The ``k`` features with the largest summed α: code, name, importance, learners."""
        imp = self.feature_importance()
        counts = np.bincount(np.asarray(self.columns)[self.booster_.weak_feature_], minlength=N_FEATURES)
        order = [int(i) for i in np.argsort(-imp, kind="stable") if imp[i] > 0][:k]
        return [
            {
                "code": FEATURES[i][0],
                "name": FEATURES[i][1],
                "importance": float(imp[i]),
                "share": float(imp[i] / imp.sum()),
                "learners": int(counts[i]),
            }
            for i in order
        ]

    def top_learners(self, k: int = 5) -> list[dict[str, Any]]:
        """The ``k`` weak learners with the largest α (book Table 8.6 ranks these): feature,
        threshold θ, polarity p (+1: person if f < θ) and α."""
        self._check_fitted()
        b = self.booster_
        order = np.argsort(-b.alpha_, kind="stable")[:k]
        out = []
        for t in order.tolist():
            col = self.columns[int(b.weak_feature_[t])]
            out.append(
                {
                    "round": int(t) + 1,
                    "code": FEATURES[col][0],
                    "name": FEATURES[col][1],
                    "threshold": float(b.weak_threshold_[t]),
                    "polarity": int(b.weak_polarity_[t]),
                    "alpha": float(b.alpha_[t]),
                }
            )
        return out

    # -- files ---------------------------------------------------------------------------

    def header(self) -> dict[str, Any]:
        """The JSON header written to a model file."""
        self._check_fitted()
        meta, _ = self.booster_.get_state()
        return {
            "format": FORMAT,
            "features": [FEATURE_CODES[c] for c in self.columns],
            "feature_names": [feature_label(c) for c in self.columns],
            "detector": {
                "jump": float(self.jump),
                "max_gap": None if self.max_gap is None else int(self.max_gap),
                "min_points": int(self.min_points),
                "max_range": None if self.max_range is None else float(self.max_range),
                "threshold": float(self.threshold),
            },
            "booster": meta,
            "training": {
                **self.training_,
                "saved": datetime.now(UTC).isoformat(timespec="seconds"),
                "version": genius_loci_version(),
            },
        }

    def save(self, path: str | Path) -> Path:
        """Write the detector to ``path`` (a ``.npz``) atomically; returns the path."""
        _, arrays = self.booster_.get_state()
        return write_npz(path, self.header(), {BOOSTER_PREFIX + k: v for k, v in arrays.items()})

    @classmethod
    def load(cls, path: str | Path | None = None) -> LegDetector:
        """Read a detector written by :meth:`save` (``None``: the bundled :data:`DEFAULT_MODEL`)."""
        p = Path(path) if path is not None else DEFAULT_MODEL
        if not p.is_file():
            hint = "reinstall genius-loci" if path is None else "check the path or run 'loci people train'"
            raise ModelError(f"{p}: no such people model file; {hint}")
        header, arrays = read_npz(
            p, what=f"genius-loci people model ({FORMAT} .npz)", retrain="retrain it with 'loci people train'"
        )
        return _from_header(p, header, arrays)


def _from_header(p: Path, header: Mapping[str, Any], arrays: Mapping[str, npt.NDArray[Any]]) -> LegDetector:
    fmt = header.get("format")
    if not isinstance(fmt, str) or not fmt.startswith(FORMAT_FAMILY):
        raise ModelError(f"{p}: not a genius-loci people model (format {fmt!r}, expected {FORMAT!r})")
    if fmt != FORMAT:
        raise ModelError(
            f"{p}: model format {fmt!r}, but this genius-loci reads {FORMAT!r}: retrain it with 'loci people train'"
        )
    codes = header.get("features")
    if not isinstance(codes, list) or not codes or not all(isinstance(c, str) for c in codes):
        raise ModelError(f"{p}: the header's 'features' must be a non-empty list of feature codes")
    unknown = [c for c in codes if c not in FEATURE_CODES]
    if unknown:
        raise ModelError(f"{p}: unknown features {unknown} (known: C.1..C.14): retrain the model")
    missing = [BOOSTER_PREFIX + k for k in STATE_ARRAYS if BOOSTER_PREFIX + k not in arrays]
    if missing or "booster" not in header:
        raise ModelError(
            f"{p}: the booster is missing ({missing or 'header'}); the file is incomplete: retrain it"
        )
    det = dict(header.get("detector") or {})
    try:
        booster = booster_from_state(
            dict(header["booster"]),
            {k[len(BOOSTER_PREFIX) :]: v for k, v in arrays.items() if k.startswith(BOOSTER_PREFIX)},
        )
        if booster.n_features_in_ != len(codes):
            raise ValueError(
                f"the booster reads {booster.n_features_in_} features, the header names {len(codes)}"
            )
        max_gap = det.get("max_gap")
        max_range = det.get("max_range")
        detector = LegDetector(
            n_rounds=int(booster.get_params()["n_rounds"]),
            columns=[FEATURE_CODES.index(c) for c in codes],
            jump=float(det.get("jump", DEFAULT_JUMP)),
            max_gap=None if max_gap is None else int(max_gap),
            min_points=int(det.get("min_points", 2)),
            max_range=None if max_range is None else float(max_range),
            threshold=float(det.get("threshold", 0.0)),
        )
        detector._check_params()
    except (ValueError, TypeError, KeyError) as exc:
        raise ModelError(
            f"{p}: the model is inconsistent ({exc}); it is damaged or was edited: retrain it"
        ) from exc
    if not isinstance(booster, GeneralizedAdaBoost):
        raise ModelError(f"{p}: a people model holds a generalized AdaBoost, not {type(booster).__name__}")
    detector.booster_ = booster
    detector.training_ = dict(header.get("training") or {})
    return detector
