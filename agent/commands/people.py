"""``loci people``: the leg detector on the legs data (book chapter 8), and people tracks.

``loci people train --out MODEL`` trains on the protocol's TRAIN split (positive_1..4 and the
first 70 % of negative_2's scans) and writes a model; ``loci people evaluate`` scores a model
(default: the bundled one) on the TEST split (positive_6..7 and the rest of negative_2) and
prints the confusion matrix in the form of the book's Tables 8.1–8.3 and the five most
important features (Table 8.6); ``--json`` prints one JSON object instead.

``loci people track RECORDING --out TRACKS.jsonl`` runs the agent's people step over a
recording (:mod:`agent.people_tracks`); ``loci people evaluate-tracks TRACKS.jsonl --truth
BAG`` scores the tracks against a leg_tracker benchmark bag's annotated people with CLEAR-MOT
(:mod:`knowledge.people.clearmot`), as the benchmark's scorer does.

The data folder is ``--data DIR``, else ``$LOCI_DATA``, else the ``../shared/data`` beside the
repository (the same rule as the tests); DIR may be that folder or its ``legs/`` sub-folder.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from agent.commands.options import positive_float, positive_int
from agent.datasets import data_dir


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "people",
        help="people in laser scans: train and evaluate the leg detector, track people, score tracks",
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
    tr.add_argument(
        "--bag",
        type=Path,
        metavar="BAG",
        help="also train on the people annotated in a leg_tracker benchmark bag (legs near an annotated "
        "person are people, segments in the -80..12 degree arc far from everyone are not)",
    )
    tr.add_argument(
        "--bag-window",
        type=float,
        nargs=2,
        metavar=("START", "END"),
        default=(-math.inf, math.inf),
        help="only the bag's scans from START to END seconds after its first scan (keep the part you "
        "score on out: e.g. --bag-window 36 1000 to score on the first 36 s)",
    )
    tr.add_argument(
        "--bag-weight",
        type=positive_float,
        default=1.0,
        metavar="W",
        help="initial weight of the bag's segments relative to the legs data's, within each class (default: 1)",
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

    tk = sub.add_parser(
        "track",
        help="detect and track people over a recording, as the agent does; write the tracks",
        description=(
            "Run the agent's people step over a recording (loci run --record, loci record, loci import; a "
            "ROS 1 bag is imported first): scans and odometry associated as in loci run, people detected, "
            "paired and tracked in the odometry frame while the robot moves. Writes JSON lines: a header, "
            "then per scan the laser's odometry pose, the detected people and the confirmed tracks."
        ),
        epilog="Example: loci people track people.mcap --out tracks.jsonl",
    )
    tk.add_argument("recording", type=Path, metavar="RECORDING", help="an MCAP recording or a ROS 1 bag")
    tk.add_argument(
        "--out", type=Path, required=True, metavar="TRACKS.jsonl", help="where to write the tracks"
    )
    tk.add_argument("--model", type=Path, metavar="M", help="leg detector (default: the bundled one)")
    tk.add_argument("--robot", help="the robot whose scans to use (default: the recording's)")
    tk.add_argument(
        "--plain",
        action="store_true",
        help="the plain tracker: no static cells, no free-space evidence, no score floor (before issue 15; for comparison)",
    )
    tk.add_argument(
        "--min-score",
        type=float,
        metavar="F",
        help="a leg needs the detector's output F >= this (default: the detector's threshold)",
    )
    tk.add_argument(
        "--min-travel",
        type=float,
        metavar="M",
        help="a new track is confirmed only once it moved M metres from where it was born (default 0)",
    )
    tk.add_argument(
        "--min-seen-through",
        type=int,
        metavar="N",
        help="scans that must have seen through a detection for it to be evidence of motion (default 3)",
    )
    tk.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    tk.set_defaults(handler=_track)

    et = sub.add_parser(
        "evaluate-tracks",
        help="score tracks against a benchmark bag's annotated people (CLEAR-MOT)",
        description=(
            "Score tracks written by loci people track against the hand-annotated people of a leg_tracker "
            "benchmark bag (/ground_truth_people_tracks), as the benchmark's scorer does: per scan, in the "
            "laser's frame, CLEAR-MOT at 0.75 m (valid, misses, false positives, identity switches, MOTA, "
            "MOTP) over the people between -80 and 12 degrees; plus precision and recall of each scan's "
            "detected people at 0.5 m."
        ),
        epilog="Example: loci people evaluate-tracks tracks.jsonl --truth general_tracking_moving_1.bag",
    )
    et.add_argument("tracks", type=Path, metavar="TRACKS.jsonl", help="written by loci people track")
    et.add_argument("--truth", type=Path, required=True, metavar="BAG", help="the annotated ROS 1 bag")
    et.add_argument(
        "--window",
        type=float,
        nargs=2,
        metavar=("START", "END"),
        default=(-math.inf, math.inf),
        help="score only the scans from START to END seconds after the bag's first scan (default: all)",
    )
    et.add_argument(
        "--arc",
        type=float,
        nargs=2,
        metavar=("MIN", "MAX"),
        default=(-80.0, 12.0),
        help="bearings in degrees, laser frame, of the people scored (default: -80 12, the benchmark's)",
    )
    et.add_argument("--all-bearings", action="store_true", help="score people at every bearing")
    et.add_argument(
        "--threshold",
        type=positive_float,
        default=0.75,
        metavar="M",
        help="CLEAR-MOT match distance (0.75 m)",
    )
    et.add_argument(
        "--coasting",
        action="store_true",
        help="also score confirmed tracks not seen in the scan (by default only tracks seen in it count)",
    )
    et.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    et.set_defaults(handler=_evaluate_tracks)


def _progress(total: int, desc: str) -> Any:
    from tqdm import tqdm

    return functools.partial(tqdm, total=total, desc=desc, unit="scan", file=sys.stderr, disable=None)


def _examples(args: argparse.Namespace, split: str, jump: float, max_gap: int | None = None) -> Any:
    from knowledge.people import dataset as ds

    legs_dir = ds.find_legs_dir(args.data if args.data is not None else data_dir())
    parts = ds.protocol_parts(split, legs_dir, max_scans=args.max_scans)
    total = ds.n_protocol_scans(legs_dir, parts)
    ex = ds.build_examples(
        legs_dir, parts, jump=jump, max_gap=max_gap, progress=_progress(total, f"{split} scans")
    )
    return legs_dir, ex


def _train(args: argparse.Namespace) -> int:
    import numpy as np

    from knowledge.people.detector import LegDetector
    from knowledge.people.features import DEFAULT_COLUMNS, FEATURE_CODES, JUMP_COLUMNS, MOTION_COLUMN

    _, ex = _examples(args, "train", args.jump)
    X, y, weight = ex.X, ex.y, None
    bag_counts: dict[str, Any] | None = None
    if args.bag is not None:
        from agent.people_tracks import bag_examples

        window = (float(args.bag_window[0]), float(args.bag_window[1]))
        Xb, yb, _, counts = bag_examples(args.bag, window=window, jump=args.jump)
        X, y = np.concatenate([ex.X, Xb]), np.concatenate([ex.y, yb])
        weight = np.concatenate([np.ones(ex.y.size), np.full(yb.size, args.bag_weight)])
        bag_counts = {"bag": str(args.bag), "window_s": list(window), "weight": args.bag_weight, **counts}
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
        + (f" --threshold {args.threshold}" if args.threshold != "sign" else "")
        + (
            f" --bag {args.bag} --bag-window {args.bag_window[0]:g} {args.bag_window[1]:g} --bag-weight {args.bag_weight:g}"
            if args.bag is not None
            else ""
        ),
    }
    if bag_counts is not None:
        training["bag"] = bag_counts

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
    det = make(threshold).fit(X, y, training=training, sample_weight=weight)
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
        "bag": bag_counts,
    }
    if args.json:
        print(json.dumps(summary, indent=None, sort_keys=True))
    else:
        print(
            f"trained on {ex.n_positive} people and {ex.n_negative} non-people segments "
            f"({ex.diagnostics['scans']} scans) in {seconds:.1f} s; "
            f"{summary['rounds']} weak learners, training error {summary['train_error_pct']:.2f}%"
        )
        if bag_counts is not None:
            print(
                f"  and on {bag_counts['people']} people and {bag_counts['non_people']} non-people segments of "
                f"{bag_counts['scans']} scans of {args.bag} (weight {args.bag_weight:g})"
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


def _track(args: argparse.Namespace) -> int:
    import dataclasses

    from agent.people_tracks import track_recording, write_tracks
    from agent.progress import Progress
    from knowledge.errors import ConfigError
    from knowledge.people.detector import LegDetector
    from knowledge.people.pipeline import (
        DEFAULT_MIN_SCORE,
        DEFAULT_MIN_SEEN_THROUGH,
        DEFAULT_TRACKER,
        PeoplePipeline,
    )
    from knowledge.people.tracking import TrackerConfig

    det = LegDetector.load(args.model)
    options = {
        k: v
        for k, v in (
            ("--min-score", args.min_score),
            ("--min-travel", args.min_travel),
            ("--min-seen-through", args.min_seen_through),
        )
        if v is not None
    }
    if args.plain and options:
        raise ConfigError(f"--plain takes none of {', '.join(options)}")
    try:
        pipe = (
            PeoplePipeline(det, tracker=TrackerConfig(), static=None, min_seen_through=0, min_score=None)
            if args.plain
            else PeoplePipeline(
                det,
                tracker=dataclasses.replace(
                    DEFAULT_TRACKER,
                    min_travel=DEFAULT_TRACKER.min_travel if args.min_travel is None else args.min_travel,
                ),
                min_seen_through=DEFAULT_MIN_SEEN_THROUGH
                if args.min_seen_through is None
                else args.min_seen_through,
                min_score=DEFAULT_MIN_SCORE if args.min_score is None else args.min_score,
            )
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
    src = args.recording
    with Progress() as progress:
        if src.suffix == ".bag":  # ROS 1: import into a temporary recording first
            import tempfile

            from agent.recording.importer import import_log

            with tempfile.TemporaryDirectory(prefix="loci-people-") as tmp:
                rec = Path(tmp) / "imported.mcap"
                import_log(src, rec, fmt="ros1", progress=progress)
                run = track_recording(
                    rec, pipe, robot=args.robot, progress=lambda d, t: progress("track", d, t or d)
                )
        else:
            run = track_recording(
                src, pipe, robot=args.robot, progress=lambda d, t: progress("track", d, t or d)
            )
    header = {
        "recording": str(src),
        "model": str(args.model) if args.model else "bundled",
        "tracker": "plain" if args.plain else ("default" if not options else "default with options"),
        "options": {k.lstrip("-"): v for k, v in options.items()},
        "command": "loci people track "
        + str(src)
        + (" --plain" if args.plain else "")
        + "".join(f" {k} {v:g}" for k, v in options.items()),
    }
    write_tracks(args.out, run, header)
    n_tracks = len({int(i) for f in run.frames for i in f.tracks[:, 0]})
    summary = {**run.summary(), "out": str(args.out), "tracks": n_tracks}
    if args.json:
        print(json.dumps(summary, sort_keys=True))
    else:
        dropped = sum(run.dropped.values())
        print(
            f"tracked {len(run.frames)} of {run.scans} scans ({dropped} dropped by the odometry association, "
            f"{run.invalid} invalid): {n_tracks} confirmed tracks; people step "
            f"{1000 * run.seconds_people / max(1, len(run.frames)):.2f} ms per scan"
        )
        print(f"wrote {args.out}")
    return 0


def _evaluate_tracks(args: argparse.Namespace) -> int:
    from agent.people_tracks import read_annotations, read_tracks, score_tracks

    header, frames = read_tracks(args.tracks)
    truth = read_annotations(args.truth)
    arc = None if args.all_bearings else (float(args.arc[0]), float(args.arc[1]))
    res = score_tracks(
        frames,
        truth,
        arc_deg=arc,
        window=(float(args.window[0]), float(args.window[1])),
        threshold=args.threshold,
        coasting=args.coasting,
    )
    out = {
        **res.as_dict(),
        "tracks": str(args.tracks),
        "truth": str(args.truth),
        "arc_deg": list(arc) if arc else None,
        "coasting": args.coasting,
        "tracker": header.get("tracker"),
    }
    if args.json:
        print(json.dumps(out, sort_keys=True))
        return 0
    m, d = res.mot, res.detections
    where = "all bearings" if arc is None else f"bearings {arc[0]:g} to {arc[1]:g} deg"
    print(
        f"{res.frames} scans, {m.objects} annotated people in {where} "
        f"({res.annotations_outside_arc} outside; {res.annotated_scans_missing} annotated scans not tracked)"
    )
    print(f"CLEAR-MOT at {m.threshold:g} m:")
    print(
        f"  valid {m.valid}  identity switches {m.id_switches}  misses {m.misses}  false positives {m.false_positives}"
    )
    mota = f"{100 * m.mota:.1f} %" if m.objects else "n/a"
    motp = f"{m.motp:.3f} m" if m.matches else "n/a"
    per = f"{m.misses / m.objects:.3f}" if m.objects else "n/a"
    print(
        f"  MOTA {mota}  MOTP {motp}  misses per annotated person {per}  "
        f"false positives per scan {m.false_positives / max(1, m.frames):.3f}"
    )
    prec = f"{100 * d.precision:.1f} %" if d.true_positives + d.false_positives else "n/a"
    rec = f"{100 * d.recall:.1f} %" if d.true_positives + d.false_negatives else "n/a"
    print(
        f"detected people per scan at {d.distance:g} m: precision {prec}, recall {rec} "
        f"({d.true_positives} found, {d.false_positives} false, {d.false_negatives} missed)"
    )
    return 0
