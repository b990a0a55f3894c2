"""CLEAR-MOT scores of people tracks against annotated people, as the leg_tracker benchmark counts them.

Bernardin & Stiefelhagen's CLEAR-MOT metrics (2008) with the rules of the scorer of the
leg_tracker benchmarks (Leigh et al., ICRA 2015), which the published numbers were made with.
The input is a sequence of *frames* (one per laser scan), each with the annotated people
(``truth``: ids and positions) and the tracker's people (``estimate``: ids and positions) in one
frame of reference, metres. Per frame, in order:

1. **kept correspondences**: every (estimate id, truth id) pair matched in an earlier frame
   (the latest match of either id) whose two ids are both present again and within
   ``threshold`` metres (strictly less) stays matched;
2. **new matches**: the remaining estimates and truths are assigned by the minimal sum of
   distances (Hungarian method over all remaining pairs, whatever their distance) and the
   assigned pairs closer than ``threshold`` are matched;
3. every unmatched estimate is a **false positive**, every unmatched truth a **miss**;
4. a match is an **identity switch** when its estimate id was last matched to another truth
   id, or when (the estimate id never matched before) its truth id was last matched to another
   estimate id; every other match is **valid** (the benchmark's "correct");
5. **MOTP** is the mean distance over all matches (switches included); **MOTA** is
   ``1 − (misses + false positives + switches) / objects``, objects = annotated positions
   (so ``objects = valid + switches + misses``).

Where this differs from the CLEAR-MOT paper (and from the ``motmetrics`` package): a
switch is also counted from the estimate's side (rule 4), a correspondence is forgotten as
soon as either id is matched to someone else, and the Hungarian step may assign a pair beyond
the threshold (then dropped) where ``motmetrics`` would assign a nearer valid pair. With one
annotated person at a time, or people far apart, the counts agree with ``motmetrics``
(tested).

:func:`detection_scores` adds per-frame precision and recall of unidentified detections
(one Hungarian matching per frame within a distance, no memory).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

__all__ = [
    "BENCHMARK_THRESHOLD",
    "ClearMot",
    "DetectionScores",
    "MotFrame",
    "clear_mot",
    "detection_scores",
]

#: The benchmark's match distance, metres.
BENCHMARK_THRESHOLD = 0.75
#: What the benchmark's Hungarian step gives pairs that may not be matched again.
_TAKEN = 99999.0


@dataclass(frozen=True, eq=False)
class MotFrame:
    """The annotated and the tracked people of one scan.

    Attributes:
        truth_ids: ``(G,)`` int, annotation ids; truth: ``(G, 2)`` metres.
        estimate_ids: ``(E,)`` int, track ids; estimate: ``(E, 2)`` metres (same frame of reference).
        stamp: the scan's time, seconds (for reports only).
    """

    truth_ids: npt.NDArray[np.int64]
    truth: npt.NDArray[np.float64]
    estimate_ids: npt.NDArray[np.int64]
    estimate: npt.NDArray[np.float64]
    stamp: float = math.nan

    @classmethod
    def of(
        cls,
        truth: Sequence[tuple[int, float, float]],
        estimate: Sequence[tuple[int, float, float]],
        stamp: float = math.nan,
    ) -> MotFrame:
        """A frame from ``(id, x, y)`` rows.

        Raises:
            ValueError: an id repeated within the truth or the estimate, or a position that is not finite.
        """
        t = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
        e = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
        for name, a in (("truth", t), ("estimate", e)):
            if not np.isfinite(a).all():
                raise ValueError(f"{name} rows must be finite (id, x, y), got {a.tolist()}")
            if np.unique(a[:, 0]).size != a.shape[0]:
                raise ValueError(f"{name} ids must be unique within a frame, got {a[:, 0].tolist()}")
        return cls(
            t[:, 0].astype(np.int64), t[:, 1:].copy(), e[:, 0].astype(np.int64), e[:, 1:].copy(), stamp
        )


@dataclass
class ClearMot:
    """CLEAR-MOT counts over a sequence (see the module doc).

    Attributes:
        valid, id_switches, misses, false_positives: event counts.
        objects: annotated positions; frames: frames scored.
        distance_sum: metres, summed over all matches (valid and switches).
        threshold: the match distance, metres.
        events: per frame ``(stamp, valid, switches, misses, false positives)`` when kept.
    """

    valid: int = 0
    id_switches: int = 0
    misses: int = 0
    false_positives: int = 0
    objects: int = 0
    frames: int = 0
    distance_sum: float = 0.0
    threshold: float = BENCHMARK_THRESHOLD
    events: list[tuple[float, int, int, int, int]] = field(default_factory=list)

    @property
    def matches(self) -> int:
        return self.valid + self.id_switches

    @property
    def mota(self) -> float:
        """``1 − (misses + false positives + switches) / objects`` (NaN without objects)."""
        if self.objects == 0:
            return math.nan
        return 1.0 - (self.misses + self.false_positives + self.id_switches) / self.objects

    @property
    def motp(self) -> float:
        """Mean distance of the matches, metres (NaN without matches)."""
        return self.distance_sum / self.matches if self.matches else math.nan

    def as_dict(self) -> dict[str, Any]:
        return {
            "threshold_m": self.threshold,
            "frames": self.frames,
            "objects": self.objects,
            "valid": self.valid,
            "id_switches": self.id_switches,
            "misses": self.misses,
            "false_positives": self.false_positives,
            "mota_pct": 100.0 * self.mota if self.objects else None,
            "motp_m": self.motp if self.matches else None,
            "misses_per_frame": self.misses / self.frames if self.frames else None,
            "false_positives_per_frame": self.false_positives / self.frames if self.frames else None,
        }


def _distances(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``(len(a), len(b))`` Euclidean distances."""
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])


def clear_mot(
    frames: Iterable[MotFrame], threshold: float = BENCHMARK_THRESHOLD, *, keep_events: bool = False
) -> ClearMot:
    """Score the frames in order (see the module doc).

    Raises:
        ValueError: ``threshold`` is not a positive number.
    """
    if not (math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be a positive distance in metres, got {threshold!r}")
    out = ClearMot(threshold=threshold)
    previous: dict[int, int] = {}  # estimate id -> truth id of its latest match
    for fr in frames:
        out.frames += 1
        G, E = fr.truth.shape[0], fr.estimate.shape[0]
        out.objects += G
        d = _distances(fr.estimate, fr.truth)
        est_ids = fr.estimate_ids.tolist()
        gt_ids = fr.truth_ids.tolist()
        matched: dict[int, int] = {}  # estimate index -> truth index
        est_at = {e: k for k, e in enumerate(est_ids)}
        gt_at = {g: k for k, g in enumerate(gt_ids)}
        for e_id, g_id in previous.items():
            i, j = est_at.get(e_id), gt_at.get(g_id)
            if i is not None and j is not None and d[i, j] < threshold:
                matched[i] = j
        if E and G:
            cost = d.copy()
            taken_g = set(matched.values())
            for i in range(E):
                for j in range(G):
                    if i in matched or j in taken_g:
                        cost[i, j] = _TAKEN
            rows, cols = linear_sum_assignment(cost)
            for i, j in zip(rows.tolist(), cols.tolist(), strict=True):
                if cost[i, j] < threshold:
                    matched[i] = j
        n_valid = n_switch = 0
        seen_truth = set(previous.values())
        for i, j in matched.items():
            e_id, g_id = est_ids[i], gt_ids[j]
            if e_id in previous:
                if previous[e_id] == g_id:
                    n_valid += 1
                else:
                    n_switch += 1
            elif g_id in seen_truth:
                n_switch += 1
            else:
                n_valid += 1
            out.distance_sum += float(d[i, j])
        n_fp = E - len(matched)
        n_miss = G - len(matched)
        out.valid += n_valid
        out.id_switches += n_switch
        out.false_positives += n_fp
        out.misses += n_miss
        if keep_events:
            out.events.append((fr.stamp, n_valid, n_switch, n_miss, n_fp))
        now = {est_ids[i]: gt_ids[j] for i, j in matched.items()}
        now_truth = set(now.values())
        previous = {e: g for e, g in previous.items() if e not in now and g not in now_truth}
        previous.update(now)
    return out


@dataclass
class DetectionScores:
    """Per-frame detections against the annotations, matched one to one within a distance.

    Attributes:
        true_positives, false_positives, false_negatives: counts over all frames.
        frames: frames scored; distance: the match distance, metres.
    """

    true_positives: int = 0
    false_positives: int = 0
    false_negatives: int = 0
    frames: int = 0
    distance: float = 0.5

    @property
    def precision(self) -> float:
        n = self.true_positives + self.false_positives
        return self.true_positives / n if n else math.nan

    @property
    def recall(self) -> float:
        n = self.true_positives + self.false_negatives
        return self.true_positives / n if n else math.nan

    def as_dict(self) -> dict[str, Any]:
        return {
            "distance_m": self.distance,
            "frames": self.frames,
            "true_positives": self.true_positives,
            "false_positives": self.false_positives,
            "false_negatives": self.false_negatives,
            "precision_pct": 100.0 * self.precision if not math.isnan(self.precision) else None,
            "recall_pct": 100.0 * self.recall if not math.isnan(self.recall) else None,
        }


def detection_scores(
    frames: Iterable[tuple[npt.ArrayLike, npt.ArrayLike]], distance: float = 0.5
) -> DetectionScores:
    """Precision and recall of ``(truth (G, 2), detections (K, 2))`` per frame: each frame's
    minimal-distance one-to-one matching, pairs within ``distance`` metres are true positives.

    Raises:
        ValueError: ``distance`` is not a positive number.
    """
    if not (math.isfinite(distance) and distance > 0):
        raise ValueError(f"distance must be a positive number of metres, got {distance!r}")
    out = DetectionScores(distance=distance)
    for truth, det in frames:
        t = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
        k = np.asarray(det, dtype=np.float64).reshape(-1, 2)
        out.frames += 1
        tp = 0
        if t.shape[0] and k.shape[0]:
            d = _distances(t, k)
            big = distance * 1e3 + 1.0
            rows, cols = linear_sum_assignment(np.where(d <= distance, d, big))
            tp = int((d[rows, cols] <= distance).sum())
        out.true_positives += tp
        out.false_negatives += t.shape[0] - tp
        out.false_positives += k.shape[0] - tp
    return out
