"""Benchmark: the bundled place models against the previous ones, in the same process.

Two timings, each run alternately for the old and the new model so that the machine's load
hits both alike, one thread:

* **whole-map labeling** of lab_intel (every free cell, 360 beams), CPU seconds, best of
  ``--repeat`` (the map models; ``docs/results/bench.md``'s labeling benchmark);
* **the agent's pipeline per scan** on the real Freiburg 079 log (front laser, local map,
  rear beams, model, HMM, navigation graph; people off), p50 and p99 of the per-scan CPU time
  (the agent models).

The target (issue 13): the new models no more than 10 % slower than the old ones.

Run: ``python -m tools.bench_places_models --old-agent OLD.npz --old-map OLD.npz``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import data_dir
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.labeling import label_map
from knowledge.places.model import PlaceModel, default_map_model_path, default_model_path


def labeling_seconds(grid: OccupancyGrid, model: PlaceModel) -> float:
    c0 = time.process_time()
    label_map(grid, model)
    return time.process_time() - c0


def pipeline_times(log: Any, model: PlaceModel, n: int) -> np.ndarray:
    """Per-scan CPU seconds of ``Pipeline.process`` over the first ``n`` scans of the log."""
    from agent.core.pipeline import PeopleParams, Pipeline, PipelineParams
    from agent.training.labelled_log import NO_ECHO
    from drivers.messages import LaserScan, Pose2D

    pipe = Pipeline(model, PipelineParams(people=PeopleParams(enabled=False)))
    out = np.empty(min(n, len(log)))
    for i in range(len(out)):
        scan = LaserScan(
            float(log.stamps[i]), i, "laser", log.angle_min, log.angle_increment, NO_ECHO, log.ranges[i]
        )
        x, y, th = (float(v) for v in log.poses[i])
        pose = Pose2D(x, y, th, stamp=float(log.stamps[i]))
        c0 = time.process_time_ns()
        pipe.process(scan, pose)
        out[i] = (time.process_time_ns() - c0) * 1e-9
    return out


def _text(r: dict[str, Any], repeat: int, scans: int) -> str:
    o, n = r["old"], r["new"]
    load0 = r["load_at_start"]
    lines: list[str] = []
    lines.append(
        f"whole-map labeling of lab_intel ({r['cells']:,} cells), best CPU of {repeat}: old {o['labeling_cpu_s']:.2f} s "
        f"({o['labeling_features']} features), new {n['labeling_cpu_s']:.2f} s ({n['labeling_features']} features): "
        f"new/old {r['ratio_labeling']:.3f}"
    )
    lines.append(
        f"pipeline per scan on the Freiburg 079 log ({scans} scans, per-scan minimum of {repeat} runs): "
        f"old p50 {o['scan_p50_ms']:.3f} ms p99 {o['scan_p99_ms']:.3f} ms; new p50 {n['scan_p50_ms']:.3f} ms "
        f"p99 {n['scan_p99_ms']:.3f} ms (HMM {'on' if n['hmm'] else 'off'}): new/old p99 {r['ratio_p99']:.3f}"
    )
    lines.append(f"load average at the start {load0[0]:.1f} on {os.cpu_count()} cores")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench_places_models", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--old-agent", type=Path, required=True, help="the previous agent model")
    ap.add_argument("--old-map", type=Path, required=True, help="the previous map model")
    ap.add_argument("--new-agent", type=Path, default=None, help="default: the bundled default.npz")
    ap.add_argument("--new-map", type=Path, default=None, help="default: the bundled default_map.npz")
    ap.add_argument("--repeat", type=int, default=3, help="labeling runs per model (best counts)")
    ap.add_argument("--scans", type=int, default=4791, help="log scans per pipeline run")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    from agent.training.labelled_log import load_fr079

    args = build_parser().parse_args(argv)
    data = args.data or data_dir()
    grid = OccupancyGrid.from_image(data / "ipa" / "labeled" / "lab_intel.map.png", 0.05)
    maps = {
        "old": PlaceModel.load(args.old_map),
        "new": PlaceModel.load(args.new_map or default_map_model_path()),
    }
    agents = {
        "old": PlaceModel.load(args.old_agent),
        "new": PlaceModel.load(args.new_agent or default_model_path()),
    }
    log = load_fr079(data)
    for m in maps.values():  # compile / load every kernel first
        label_map(grid, m, cells=grid.free_cells()[:64])
    for m in agents.values():
        pipeline_times(log, m, 20)
    lab: dict[str, list[float]] = {"old": [], "new": []}
    per_scan: dict[str, list[np.ndarray]] = {"old": [], "new": []}
    load0 = os.getloadavg()
    for _ in range(args.repeat):
        for k in ("old", "new"):
            lab[k].append(labeling_seconds(grid, maps[k]))
            per_scan[k].append(pipeline_times(log, agents[k], args.scans))
    res: dict[str, Any] = {"load_at_start": load0, "cells": int(grid.free.sum())}
    for k in ("old", "new"):
        t = np.min(np.stack(per_scan[k]), axis=0)  # per scan, the least disturbed of the runs
        res[k] = {
            "labeling_cpu_s": min(lab[k]),
            "labeling_features": len(maps[k].prediction_columns()),
            "scan_p50_ms": float(np.percentile(t, 50) * 1e3),
            "scan_p99_ms": float(np.percentile(t, 99) * 1e3),
            "agent_features": len(agents[k].prediction_columns()),
            "hmm": agents[k].hmm is not None,
        }
    o, n = res["old"], res["new"]
    res["ratio_labeling"] = n["labeling_cpu_s"] / o["labeling_cpu_s"]
    res["ratio_p99"] = n["scan_p99_ms"] / o["scan_p99_ms"]
    emit_result(args, res, lambda r: _text(r, args.repeat, args.scans))
    return 0


if __name__ == "__main__":
    sys.exit(main())
