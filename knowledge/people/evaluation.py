"""Scores of the leg detector in the form of the book's Tables 8.1–8.3 and 8.6.

A confusion matrix has rows *true* label (people, non-people) and columns *detected* label,
each cell a count and its percentage of the row, plus the row total. The false-negative rate
is the share of people segments detected as non-people, the false-positive rate the share of
non-people segments detected as people. The same matrix weighted by each segment's number of
points gives the per-beam scores (every beam of a segment carries the segment's label).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.people.dataset import Examples
from knowledge.people.detector import LegDetector
from knowledge.people.features import FEATURE_CODES

SCHEMA = "loci.people-evaluation/1"
#: The issue's targets, percent.
TARGET_FALSE_NEGATIVES = 3.0
TARGET_FALSE_POSITIVES = 3.0


def _pct(a: float, b: float) -> float:
    return 100.0 * a / b if b else 0.0


@dataclass(frozen=True)
class Confusion:
    """Counts (or weights) of a binary confusion matrix, person = positive."""

    tp: float
    fn: float
    fp: float
    tn: float

    @classmethod
    def of(
        cls, truth: npt.ArrayLike, detected: npt.ArrayLike, weights: npt.ArrayLike | None = None
    ) -> Confusion:
        """From ``(n,)`` bool truth and detection, optionally weighted ``(n,)``."""
        t = np.asarray(truth, dtype=bool)
        d = np.asarray(detected, dtype=bool)
        if t.shape != d.shape or t.ndim != 1:
            raise ValueError(f"truth {t.shape} and detected {d.shape} must be equal 1-D shapes")
        w = np.ones(t.shape) if weights is None else np.asarray(weights, dtype=np.float64)
        return cls(
            tp=float(w[t & d].sum()),
            fn=float(w[t & ~d].sum()),
            fp=float(w[~t & d].sum()),
            tn=float(w[~t & ~d].sum()),
        )

    @property
    def people(self) -> float:
        return self.tp + self.fn

    @property
    def non_people(self) -> float:
        return self.fp + self.tn

    @property
    def false_negative_rate(self) -> float:
        """Percent of people detected as non-people."""
        return _pct(self.fn, self.people)

    @property
    def false_positive_rate(self) -> float:
        """Percent of non-people detected as people."""
        return _pct(self.fp, self.non_people)

    @property
    def total_error(self) -> float:
        return _pct(self.fn + self.fp, self.people + self.non_people)

    def to_json(self) -> dict[str, Any]:
        def num(v: float) -> float | int:
            return int(v) if float(v).is_integer() else v

        return {
            "people": {
                "people": num(self.tp),
                "people_pct": _pct(self.tp, self.people),
                "non_people": num(self.fn),
                "non_people_pct": _pct(self.fn, self.people),
                "total": num(self.people),
            },
            "non_people": {
                "people": num(self.fp),
                "people_pct": _pct(self.fp, self.non_people),
                "non_people": num(self.tn),
                "non_people_pct": _pct(self.tn, self.non_people),
                "total": num(self.non_people),
            },
            "false_negative_rate_pct": self.false_negative_rate,
            "false_positive_rate_pct": self.false_positive_rate,
            "total_error_pct": self.total_error,
        }

    def table(self, title: str = "") -> str:
        """The matrix as text laid out like the book's Tables 8.1–8.3."""
        rows = [
            ("True label", "Person", "No person", "Total"),
            (
                "Person",
                f"{self.tp:.0f} ({_pct(self.tp, self.people):.2f}%)",
                f"{self.fn:.0f} ({_pct(self.fn, self.people):.2f}%)",
                f"{self.people:.0f}",
            ),
            (
                "No person",
                f"{self.fp:.0f} ({_pct(self.fp, self.non_people):.2f}%)",
                f"{self.tn:.0f} ({_pct(self.tn, self.non_people):.2f}%)",
                f"{self.non_people:.0f}",
            ),
        ]
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        lines = [title] if title else []
        lines.append(" " * (widths[0] + 2) + "Detected label")
        for r in rows:
            lines.append(
                "  ".join(
                    c.ljust(w) if i == 0 else c.rjust(w)
                    for i, (c, w) in enumerate(zip(r, widths, strict=True))
                )
            )
        return "\n".join(lines)


def evaluate(detector: LegDetector, examples: Examples, *, split: str = "test") -> dict[str, Any]:
    """Score ``detector`` on labelled segments: one JSON-able dict (schema ``loci.people-evaluation/1``)."""
    pred = detector.predict(examples.X, examples.distance) if examples.X.shape[0] else np.zeros(0, dtype=bool)
    seg = Confusion.of(examples.y, pred)
    beams = Confusion.of(examples.y, pred, weights=examples.X[:, 0])
    per_file = []
    for pi, part in enumerate(examples.parts):
        m = examples.part == pi
        c = Confusion.of(examples.y[m], pred[m])
        per_file.append(
            {
                "file": part.file,
                "scans": [part.first, part.stop],
                "people": int(c.people),
                "non_people": int(c.non_people),
                "false_negatives": int(c.fn),
                "false_positives": int(c.fp),
            }
        )
    return {
        "schema": SCHEMA,
        "split": split,
        "confusion": seg.to_json(),
        "false_negative_rate_pct": seg.false_negative_rate,
        "false_positive_rate_pct": seg.false_positive_rate,
        "total_error_pct": seg.total_error,
        "targets": {
            "false_negative_rate_pct": TARGET_FALSE_NEGATIVES,
            "false_positive_rate_pct": TARGET_FALSE_POSITIVES,
            "met": bool(
                seg.false_negative_rate <= TARGET_FALSE_NEGATIVES
                and seg.false_positive_rate <= TARGET_FALSE_POSITIVES
            ),
        },
        "beams": beams.to_json(),
        "top_features": detector.top_features(5),
        "top_learners": detector.top_learners(5),
        "per_file": per_file,
        "diagnostics": dict(examples.diagnostics),
        "detector": {
            "features": [FEATURE_CODES[c] for c in detector.columns],
            "n_rounds": int(detector.booster_.n_rounds_),
            "jump": detector.jump,
            "max_gap": detector.max_gap,
            "min_points": detector.min_points,
            "max_range": detector.max_range,
            "threshold": detector.threshold,
        },
    }


def format_report(result: dict[str, Any]) -> str:
    """A readable report of :func:`evaluate`'s result."""
    c = result["confusion"]
    seg = Confusion(
        c["people"]["people"],
        c["people"]["non_people"],
        c["non_people"]["people"],
        c["non_people"]["non_people"],
    )
    b = result["beams"]
    beams = Confusion(
        b["people"]["people"],
        b["people"]["non_people"],
        b["non_people"]["people"],
        b["non_people"]["non_people"],
    )
    t = result["targets"]
    lines = [
        seg.table(f"Segments ({result['split']} split): confusion matrix as in Tables 8.1-8.3"),
        "",
        f"false negatives: {seg.false_negative_rate:.2f}%  (target <= {t['false_negative_rate_pct']:.0f}%)",
        f"false positives: {seg.false_positive_rate:.2f}%  (target <= {t['false_positive_rate_pct']:.0f}%)",
        f"total error:     {seg.total_error:.2f}%   targets {'met' if t['met'] else 'NOT met'}",
        "",
        beams.table("Beams (each beam carries its segment's label)"),
        "",
        "Five most important features (Table 8.6; summed weight of their weak learners):",
    ]
    for i, f in enumerate(result["top_features"], 1):
        lines.append(
            f"  {i}. {f['code']:<5} {f['name']:<24} {f['share'] * 100:5.1f}% of the weight, {f['learners']} learners"
        )
    lines.append("Five strongest single weak learners (largest alpha):")
    for i, f in enumerate(result["top_learners"], 1):
        rel = "<" if f["polarity"] > 0 else ">"
        lines.append(
            f"  {i}. round {f['round']:<3} {f['code']:<5} {f['name']:<24} person if f {rel} {f['threshold']:.4g}  alpha {f['alpha']:.3f}"
        )
    lines.append("Per file:")
    for f in result["per_file"]:
        lines.append(
            f"  {f['file']:<42} people {f['people']:>5} (FN {f['false_negatives']:>4})  "
            f"non-people {f['non_people']:>6} (FP {f['false_positives']:>5})"
        )
    det = result["detector"]
    reach = (
        "no range limit"
        if det.get("max_range") is None
        else f"segments beyond {det['max_range']:g} m are non-persons"
    )
    lines.append(
        f"Detector: features {','.join(det['features'])}; T = {det['n_rounds']}; jump {det['jump']:g} m; "
        f"{reach}; threshold {det['threshold']:g}"
    )
    d = result["diagnostics"]
    lines.append(
        f"Labels: {d.get('scans', 0)} scans, {d.get('legs', 0)} labelled legs of which {d.get('legs_matched', 0)} have a "
        f"segment within 5 cm; {d.get('near_leg_negatives', 0)} in-arc negatives lie within 0.3 m of a labelled leg."
    )
    return "\n".join(lines)
