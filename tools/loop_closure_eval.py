"""Loop closure measured offline: the pose graph over a replay's tracked keyframes (issue 26).

A recording with reference poses (``loci import RAW.log.gz REC.mcap --reference
CORRECTED.log.gz``) is replayed with pose tracking (:func:`agent.recording.loop_closure.collect_tracked`),
its keyframes go into the pose graph (:mod:`knowledge.localization.pose_graph`), loops are
closed and the graph optimised; printed: the ATE of the raw odometry, the tracked poses and the
optimised poses against the reference, with the loops' counts and the optimisation's time::

    python -m tools.loop_closure_eval REC.mcap [--work DIR] [--json]
    python -m tools.loop_closure_eval --csail [--work DIR]   # imports the raw CSAIL log first

``--fr079`` runs the same on Freiburg 079 (corrected poses as reference) with the noisy
odometry made up by ``tools.evaluate_localization`` (its log has no raw odometry), tracked with
the tracker directly: the building the parameters were checked on besides CSAIL.
The replay's arrays are cached in ``--work`` (``<name>_tracked.npz``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.datasets import data_dir
from agent.recording.loop_closure import TrackedRun, collect_tracked, evaluate_loop_closure
from knowledge.localization.pose_graph import PoseGraphParams
from knowledge.localization.scan_matching import scan_points


def csail_recording(work: Path) -> Path:
    """The raw CSAIL log imported with the corrected copy's poses as reference (in ``work``)."""
    from agent.recording.importer import import_log
    from agent.recording.reference import add_reference

    rec = work / "csail.mcap"
    if not rec.is_file():
        logs = data_dir() / "logs"
        raw = work / "csail-raw.mcap"
        import_log(logs / "csail-oldcarmen.log.gz", raw, overwrite=True, emit=lambda s: None)
        add_reference(raw, logs / "csail-corrected.log.gz", rec, overwrite=True)
    return rec


def tracked_run(rec: Path, work: Path) -> TrackedRun:
    cache = work / f"{rec.stem}_tracked.npz"
    if cache.is_file():
        return TrackedRun.load(cache)
    run = collect_tracked(rec)
    run.save(cache)
    return run


def fr079_run(work: Path) -> TrackedRun:
    """Freiburg 079 with made-up noisy odometry, tracked by the tracker (cached in ``work``)."""
    cache = work / "fr079_tracked.npz"
    if cache.is_file():
        return TrackedRun.load(cache)
    from knowledge.localization.tracking import PoseTracker
    from tools.evaluate_localization import fr079_run as arrays

    d = arrays(work)
    tracker = PoseTracker()
    rmax = float(d["range_max"])
    t0 = time.perf_counter()
    tracked = np.array(
        [
            tracker.update(r, d["angles"], o, range_max=rmax).pose
            for r, o in zip(d["ranges"], d["odom"], strict=True)
        ]
    )
    stamps = np.asarray(d["stamps"], dtype=np.float64)
    pairs = d["pairs"]
    run = TrackedRun(
        name="fr079 (noisy odometry)",
        stamps=stamps,
        points=[
            scan_points(r, d["angles"], range_max=rmax, max_range=20.0).astype(np.float32)
            for r in d["ranges"]
        ],
        odom=np.asarray(d["odom"], dtype=np.float64),
        tracked=tracked,
        truth_stamps=stamps[pairs[:, 0]],
        truth=np.asarray(d["truth"])[pairs[:, 1]],
        replay_seconds=time.perf_counter() - t0,
    )
    run.save(cache)
    return run


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.loop_closure_eval", description=__doc__.split("\n")[0])
    ap.add_argument("recording", nargs="?", type=Path, help="an MCAP recording with pose/truth")
    ap.add_argument("--csail", action="store_true", help="import and use the raw CSAIL log")
    ap.add_argument("--fr079", action="store_true", help="Freiburg 079 with made-up noisy odometry")
    ap.add_argument("--work", type=Path, default=Path("build/loop_closure"), help="cache folder")
    ap.add_argument(
        "--source", choices=("tracked", "odometry"), default="tracked", help="the graph's input poses"
    )
    ap.add_argument("--json", action="store_true", help="print the report as one JSON object")
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    if args.fr079:
        run = fr079_run(args.work)
    else:
        rec = csail_recording(args.work) if args.csail else args.recording
        if rec is None:
            ap.error("name a recording, or --csail or --fr079")
        run = tracked_run(rec, args.work)
    params = PoseGraphParams()
    report, graph = evaluate_loop_closure(run, params, source=args.source)
    out: dict[str, Any] = {"run": run.name, "source": args.source, **report.as_dict()}
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(
        f"{run.name}: {report.scans} scans, {report.keyframes} keyframes, {report.references} reference poses"
    )
    print(f"  loops: {report.loops} accepted of {report.checks} candidates ({report.reasons})")
    print(
        f"  ATE: raw odometry {report.ate_odometry:.3f} m, tracked {report.ate_tracked:.3f} m, "
        f"optimised {report.ate_optimised:.3f} m; at the {report.keyframe_references} keyframes with "
        f"a reference: optimised {report.ate_keyframes:.3f} m, tracked {report.ate_tracked_keyframes:.3f} m"
    )
    print(
        f"  optimisations: {len(graph.optimisations)}, mean {report.optimisation_ms[0]:.1f} ms, "
        f"max {report.optimisation_ms[1]:.1f} ms, at most {report.iterations_max} iterations; "
        f"pose graph {report.seconds:.1f} s over the run (replay {run.replay_seconds:.1f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
