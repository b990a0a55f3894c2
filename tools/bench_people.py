"""Benchmark: people detection time per 768-beam scan against the 75 Hz real-time budget.

Each scan goes through :class:`~knowledge.people.pipeline.PeoplePipeline` — segmentation,
features C.1–C.14, classification (the bundled detector, T = 100), pairing and tracking —
and its wall time is measured. The baseline is the scanner: at 75 scans per second a scan
must be done in 13.3 ms; ``budget_ratio`` = budget / p99 says how many times faster than
real time the p99 scan is (> 1 is real time). A second pass times the stages separately; a third gives every scan a moving odometry pose,
so that the static cells and the free-space evidence run as in the agent.

Scans: the legs data's TEST split scans (positive_6, the rear laser's negative_2 test scans)
when the data folder is there, else scans of simulated people walking in a ray-cast room.

    python -m tools.bench_people [--data DIR] [--scans 600] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result

#: Scans per second the budget is computed for (SICK LMS 2xx at its fastest, and the issue's target).
RATE_HZ = 75.0
N_BEAMS = 768
INC = 0.006135923322290182
ANGLE_MIN = -2.356194496154785
RANGE_MAX = 11.0


def real_scans(data: Path, n: int) -> tuple[np.ndarray, float, float, float, float, str] | None:
    """Up to ``n`` scans ``(n, B)`` of the legs data's test split and their geometry
    (angle_min, angle_increment, range_max, range_min), or None."""
    from knowledge.people import dataset as ds

    try:
        legs = ds.find_legs_dir(data)
        recs = [
            ds.load_recording(legs / "positive_6_extracted.training_scan.npz"),
            ds.load_recording(legs / "negative_2.rear_scan.npz"),
        ]
    except ds.DataError:
        return None
    cut = math.floor(ds.TRAIN_FRACTION * recs[1].n_scans)
    R = np.concatenate([recs[0].ranges, recs[1].ranges[cut:]])
    reps = math.ceil(n / R.shape[0])
    R = np.tile(R, (reps, 1))[:n]
    r0 = recs[0]
    return (
        R,
        r0.angle_min,
        r0.angle_increment,
        r0.range_max,
        r0.range_min,
        "legs data (positive_6 + negative_2.rear test scans)",
    )


def simulated_scans(n: int, seed: int = 0) -> tuple[np.ndarray, float, float, float, float, str]:
    """``n`` scans of three people walking in a 10 m room with a pillar (virtual LMS, 768 beams)."""
    from knowledge.metric.grid import OccupancyGrid
    from sim.lms_world import LmsWorld
    from sim.people import legs_of, walkers_in

    occ = np.zeros((200, 200), dtype=bool)
    occ[:3] = occ[-3:] = True
    occ[:, :3] = occ[:, -3:] = True
    occ[40:50, 120:126] = True
    grid = OccupancyGrid.from_masks(occ, 0.05, name="bench room")
    pose = (5.0, 5.0, 0.0)
    world = LmsWorld(grid, pose, legs_of(walkers_in(grid, pose[:2], 3, seed=seed)), seed=seed)
    fov = INC * (N_BEAMS - 1)
    R = np.stack(
        [
            world.ranges(i / RATE_HZ, n_beams=N_BEAMS, fov=fov, max_range=RANGE_MAX, angle_min=ANGLE_MIN)
            for i in range(n)
        ]
    )
    return R, ANGLE_MIN, INC, RANGE_MAX, 0.0, "simulated people in a ray-cast room"


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) * 1e3


def run(data: Path | None = None, *, n_scans: int = 600, warmup: int = 20) -> dict[str, Any]:
    """Time the pipeline per scan; returns milliseconds (p50/p99/mean/max) and ratios to the budget."""
    from knowledge.people.detector import LegDetector
    from knowledge.people.features import segment_features
    from knowledge.people.pairing import pair_legs
    from knowledge.people.pipeline import PeoplePipeline
    from knowledge.people.segmentation import segment_scan
    from knowledge.people.tracking import PeopleTracker

    if n_scans < 1:
        raise ValueError("n_scans must be >= 1")
    src = real_scans(data, n_scans) if data is not None else None
    R, amin, inc, rmax, rmin, source = src if src is not None else simulated_scans(n_scans)
    det = LegDetector.load()
    period = 1.0 / RATE_HZ

    pipe = PeoplePipeline(det)
    for i in range(min(warmup, n_scans)):
        pipe.process(R[i], i * period, angle_min=amin, angle_increment=inc, range_max=rmax, range_min=rmin)
    pipe = PeoplePipeline(det)
    total = np.empty(n_scans)
    n_segments = np.empty(n_scans)
    n_legs = np.empty(n_scans)
    cpu0 = time.process_time()
    for i in range(n_scans):
        t0 = time.perf_counter()
        frame = pipe.process(
            R[i], i * period, angle_min=amin, angle_increment=inc, range_max=rmax, range_min=rmin
        )
        total[i] = time.perf_counter() - t0
        n_segments[i] = frame.detection.segmentation.n_segments
        n_legs[i] = frame.legs.shape[0]
    cpu = time.process_time() - cpu0

    # the agent's case: a moving laser with its odometry pose, so the static cells and the
    # free-space evidence run too (the pose drives at 1 m/s: the timing, not the scene, matters)
    pipe = PeoplePipeline(det)
    posed = np.empty(n_scans)
    for i in range(n_scans):
        t0 = time.perf_counter()
        pipe.process(
            R[i],
            i * period,
            angle_min=amin,
            angle_increment=inc,
            range_max=rmax,
            range_min=rmin,
            sensor_pose=(i * period * 1.0, 0.0, 0.0),
        )
        posed[i] = time.perf_counter() - t0

    stages = np.empty((n_scans, 4))
    tracker = PeopleTracker()
    cols = list(det.columns)
    for i in range(n_scans):
        t0 = time.perf_counter()
        seg = segment_scan(
            R[i], amin, inc, range_max=rmax, range_min=rmin, jump=det.jump, max_gap=det.max_gap
        )
        X = segment_features(seg, range_max=rmax, range_min=rmin)
        t1 = time.perf_counter()
        big = det.classifies(seg.sizes, np.hypot(*seg.centroids().T))
        score = det.booster_.decision_function(X[big][:, cols]) if big.any() else np.zeros(0)
        legs = seg.centroids()[big][score >= det.threshold]
        t2 = time.perf_counter()
        people = pair_legs(legs)
        t3 = time.perf_counter()
        tracker.update(people.positions, i * period)
        t4 = time.perf_counter()
        stages[i] = (t1 - t0, t2 - t1, t3 - t2, t4 - t3)

    budget = 1.0 / RATE_HZ
    p99 = float(np.percentile(total, 99))
    return {
        "benchmark": "people_detection",
        "source": source,
        "scans": n_scans,
        "beams": int(R.shape[1]),
        "rate_hz": RATE_HZ,
        "budget_ms": round(budget * 1e3, 3),
        "p50_ms": round(_pct(total, 50), 3),
        "p99_ms": round(p99 * 1e3, 3),
        "mean_ms": round(float(total.mean()) * 1e3, 3),
        "max_ms": round(float(total.max()) * 1e3, 3),
        "cpu_ms_per_scan": round(cpu / n_scans * 1e3, 3),
        "budget_ratio": round(budget / p99, 2),
        "p99_share_of_budget": round(p99 / budget, 3),
        "with_pose_p50_ms": round(_pct(posed, 50), 3),
        "with_pose_p99_ms": round(_pct(posed, 99), 3),
        "with_pose_budget_ratio": round(budget / float(np.percentile(posed, 99)), 2),
        "segments_per_scan": round(float(n_segments.mean()), 1),
        "legs_per_scan": round(float(n_legs.mean()), 2),
        "stages_p50_ms": {
            name: round(_pct(stages[:, k], 50), 3)
            for k, name in enumerate(("segmentation_features", "classification", "pairing", "tracking"))
        },
    }


def report(r: dict[str, Any]) -> str:
    """The result as text."""
    s = r["stages_p50_ms"]
    return "\n".join(
        [
            f"People detection per {r['beams']}-beam scan, {r['scans']} scans of {r['source']}",
            f"  budget at {r['rate_hz']:g} Hz: {r['budget_ms']} ms (baseline)",
            f"  p50 {r['p50_ms']} ms, p99 {r['p99_ms']} ms, max {r['max_ms']} ms  "
            f"-> p99 is {r['budget_ratio']}x faster than real time ({100 * r['p99_share_of_budget']:.1f}% of the budget)",
            f"  with the laser's odometry pose (static cells, free-space evidence): p50 {r['with_pose_p50_ms']} ms, "
            f"p99 {r['with_pose_p99_ms']} ms -> {r['with_pose_budget_ratio']}x faster than real time",
            f"  stages (p50): segmentation+features {s['segmentation_features']} ms, classification "
            f"{s['classification']} ms, pairing {s['pairing']} ms, tracking {s['tracking']} ms",
            f"  {r['segments_per_scan']} segments and {r['legs_per_scan']} legs per scan on average",
        ]
    )


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_people", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--data", type=Path, help="the shared data folder (default: $LOCI_DATA or ../shared/data)"
    )
    ap.add_argument("--sim", action="store_true", help="use simulated scans even if the data is there")
    ap.add_argument("--scans", type=int, default=600, help="scans to time (default: 600)")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    from agent.datasets import data_dir

    args = build_parser().parse_args(argv)
    data = None if args.sim else (args.data or data_dir())
    r = run(data, n_scans=args.scans)
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
