"""``loci people``: train and evaluate the leg detector on the legs data (book chapter 8).

``loci people train --out MODEL`` trains on the protocol's TRAIN split (positive_1..4 and the
first 70 % of negative_2's scans) and writes a model; ``loci people evaluate`` scores a model
(default: the bundled one) on the TEST split (positive_6..7 and the rest of negative_2) and
prints the confusion matrix in the form of the book's Tables 8.1–8.3 and the five most
important features (Table 8.6); ``--json`` prints one JSON object instead.

The data folder is ``--data DIR``, else ``$LOCI_DATA``, else the ``../shared/data`` beside the
repository (the same rule as the tests); DIR may be that folder or its ``legs/`` sub-folder.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from agent.commands.options import positive_float, positive_int

#: The repository root (agent/commands/people.py → two levels up).
REPO = Path(__file__).resolve().parents[2]


def default_data_dir() -> Path:
    """``$LOCI_DATA``, else ``../shared/data`` beside the repository."""
    env = os.environ.get("LOCI_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "people",
        help="people in laser scans: train and evaluate the leg detector",
        description=(
            "People in laser scans (book chapter 8): jump-distance segments, the 14 features of "
            "appendix C, generalized AdaBoost with T = 100 threshold learners."
        ),
    )
    sub = p.add_subparsers(dest="people_command", metavar="ACTION", required=True)

    def common(q: argparse.ArgumentParser) -> None:
        q.add_argument(
            "--data",
            type=Path,
            metavar="DIR",
            help="the shared data folder (or its legs/ sub-folder); default $LOCI_DATA, else ../shared/data "
            "beside the repository",
        )
        q.add_argument(
            "--max-scans",
            type=positive_int,
            metavar="N",
            help="use only the first N scans of each file of the split (quick runs)",
        )
        q.add_argument("--json", action="store_true", help="print one JSON object instead of text")

    tr = sub.add_parser(
        "train",
        help="train a detector on the protocol's TRAIN split",
        description=(
            "Train the leg detector on positive_1..4 and the first 70% of negative_2's scans "
            "(all three lasers) and write it as a .npz model."
        ),
        epilog="Example: loci people train --out knowledge/people/models/legs_default.npz",
    )
    common(tr)
    tr.add_argument(
        "--out", type=Path, required=True, metavar="MODEL", help="where to write the model (.npz)"
    )
    tr.add_argument("--rounds", type=positive_int, default=100, help="boosting rounds T (default: 100)")
    tr.add_argument(
        "--motion",
        action="store_true",
        help="also use C.14 (mean speed between consecutive scans); off by default, see docs/people.md",
    )
    tr.add_argument(
        "--jumps",
        action="store_true",
        help="also use C.4/C.5 (jump distances to the neighbouring beams); off by default: in the legs data "
        "they learn the empty space the labelled people stand in, see docs/people.md",
    )
    tr.add_argument(
        "--jump", type=positive_float, default=0.15, help="jump distance in metres (default: 0.15)"
    )
    tr.add_argument(
        "--max-range",
        type=positive_float,
        default=5.0,
        metavar="M",
        help="the detector never calls a segment whose centroid is farther than M metres a person "
        "(default: 5, the reach of the data's labels; a large value means no limit)",
    )
    tr.add_argument(
        "--threshold",
        choices=("sign", "train-cv"),
        default="sign",
        help="decision threshold on F: 'sign' (F >= 0, the book's; default) or 'train-cv' (the one that "
        "minimises max(FN, FP) in a 4-fold cross-validation on the TRAIN split; the test split is never used)",
    )
    tr.set_defaults(handler=_train)

    ev = sub.add_parser(
        "evaluate",
        help="score a detector on the protocol's TEST split",
        description=(
            "Score a detector on positive_6..7 and the last 30% of negative_2's scans: confusion "
            "matrix (Tables 8.1-8.3), false-negative and false-positive rates, five most important "
            "features (Table 8.6)."
        ),
    )
    common(ev)
    ev.add_argument("--model", type=Path, metavar="M", help="model file (default: the bundled detector)")
    ev.add_argument(
        "--split", choices=("test", "train"), default="test", help="which split to score (default: test)"
    )
    ev.set_defaults(handler=_evaluate)


def _progress(total: int, desc: str) -> Any:
    from tqdm import tqdm

    return functools.partial(tqdm, total=total, desc=desc, unit="scan", file=sys.stderr, disable=None)


def _examples(args: argparse.Namespace, split: str, jump: float, max_gap: int | None = None) -> Any:
    from knowledge.people import dataset as ds

    legs_dir = ds.find_legs_dir(args.data if args.data is not None else default_data_dir())
    parts = ds.protocol_parts(split, legs_dir, max_scans=args.max_scans)
    total = ds.n_protocol_scans(legs_dir, parts)
    ex = ds.build_examples(
        legs_dir, parts, jump=jump, max_gap=max_gap, progress=_progress(total, f"{split} scans")
    )
    return legs_dir, ex


def _train(args: argparse.Namespace) -> int:
    from knowledge.people.detector import LegDetector
    from knowledge.people.features import DEFAULT_COLUMNS, FEATURE_CODES, JUMP_COLUMNS, MOTION_COLUMN

    _, ex = _examples(args, "train", args.jump)
    if ex.n_positive == 0 or ex.n_negative == 0:
        print(
            f"loci: error: the TRAIN split gave {ex.n_positive} people and {ex.n_negative} non-people segments; "
            "both are needed (use more scans)",
            file=sys.stderr,
        )
        return 2
    columns = sorted(
        set(DEFAULT_COLUMNS)
        | (set(JUMP_COLUMNS) if args.jumps else set())
        | ({MOTION_COLUMN} if args.motion else set())
    )
    training = {
        "protocol": "train",
        "files": [[p.file, p.first, p.stop] for p in ex.parts],
        "people_segments": ex.n_positive,
        "non_people_segments": ex.n_negative,
        "diagnostics": dict(ex.diagnostics),
        "command": "loci people train"
        + (" --motion" if args.motion else "")
        + (" --jumps" if args.jumps else "")
        + (f" --rounds {args.rounds}" if args.rounds != 100 else "")
        + (f" --jump {args.jump:g}" if args.jump != 0.15 else "")
        + (f" --max-range {args.max_range:g}" if args.max_range != 5.0 else "")
        + (f" --max-scans {args.max_scans}" if args.max_scans else "")
        + (f" --threshold {args.threshold}" if args.threshold != "sign" else ""),
    }

    def make(threshold: float = 0.0) -> LegDetector:
        return LegDetector(
            n_rounds=args.rounds,
            columns=columns,
            jump=args.jump,
            max_range=args.max_range,
            threshold=threshold,
        )

    t0 = time.perf_counter()
    threshold = 0.0
    if args.threshold == "train-cv":
        from knowledge.people.threshold import balanced_threshold, cv_folds, out_of_fold_scores

        folds = cv_folds(ex)
        choice = balanced_threshold(
            out_of_fold_scores(make, ex.X, ex.y, folds), ex.y, make().classifies(ex.X[:, 0], ex.distance)
        )
        threshold = choice.threshold
        training["threshold_cv"] = {
            "folds": int(folds.max()) + 1,
            "threshold": choice.threshold,
            "false_negative_rate_pct": choice.false_negative_rate_pct,
            "false_positive_rate_pct": choice.false_positive_rate_pct,
        }
    det = make(threshold).fit(ex.X, ex.y, training=training)
    seconds = time.perf_counter() - t0
    path = det.save(args.out)
    summary = {
        "model": str(path),
        "people_segments": ex.n_positive,
        "non_people_segments": ex.n_negative,
        "features": [FEATURE_CODES[c] for c in columns],
        "rounds": int(det.booster_.n_rounds_),
        "train_error_pct": 100.0 * float(det.booster_.train_error_),
        "fit_seconds": seconds,
        "top_features": det.top_features(5),
        "threshold": det.threshold,
    }
    if args.json:
        print(json.dumps(summary, indent=None, sort_keys=True))
    else:
        print(
            f"trained on {ex.n_positive} people and {ex.n_negative} non-people segments "
            f"({ex.diagnostics['scans']} scans) in {seconds:.1f} s; "
            f"{summary['rounds']} weak learners, training error {summary['train_error_pct']:.2f}%"
        )
        print(
            "most important features: "
            + ", ".join(f"{f['code']} {f['name']}" for f in summary["top_features"])
        )
        if args.threshold == "train-cv":
            cv = training["threshold_cv"]
            print(
                f"threshold {det.threshold:.4g} from {cv['folds']}-fold cross-validation on the TRAIN split "
                f"(there: FN {cv['false_negative_rate_pct']:.2f}%, FP {cv['false_positive_rate_pct']:.2f}%)"
            )
        print(f"wrote {path}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from knowledge.people.detector import LegDetector
    from knowledge.people.evaluation import evaluate, format_report

    det = LegDetector.load(args.model)
    legs_dir, ex = _examples(args, args.split, det.jump, det.max_gap)
    result = evaluate(det, ex, split=args.split)
    result["model"] = str(args.model) if args.model is not None else "bundled"
    result["data"] = str(legs_dir)
    if args.json:
        print(json.dumps(result, sort_keys=True))
    else:
        print(format_report(result))
    return 0
