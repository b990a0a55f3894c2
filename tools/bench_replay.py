"""Benchmark: replaying a real robot log, per scan and as a whole, against the log's own pace.

The real Freiburg 079 log (4,791 scans of a SICK LMS, 360 beams over 180°, 17.7 min) is
imported with ``loci import`` and replayed as ``loci replay`` does it (decode, odometry
association, the pipeline with people on, navigation graph and areas). Measured:

* **replay**: the whole file's wall time and scans per second; the baseline is the log's own
  pace (its scans over its duration): ``× real time`` says how many times faster than the
  robot recorded it the agent gets through it;
* **per scan**: the time of :meth:`~agent.core.pipeline.Pipeline.process` on each real scan (p50,
  p99, max), with people on (the default) and off, in the same process; the ratio against the
  laser's period at the LMS's fastest rate (75 Hz: 13.3 ms) says how much room is left.

Without ``../shared/data`` (or ``$LOCI_DATA``) it says so and exits 2.

    python -m tools.bench_replay [--scans N] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import data_dir

DATA = data_dir()
LOG = "logs/freiburg-079-corrected.log.gz"
RATE_HZ = 75.0


def per_scan(path: Path, model: Any, people: bool, limit: int | None) -> np.ndarray:
    """Milliseconds of each ``Pipeline.process`` over the recording's matched scans."""
    from dataclasses import replace

    from agent.core.odom_sync import Matched, SyncParams
    from agent.core.pipeline import PeopleParams, Pipeline, PipelineParams
    from agent.core.sensor_loop import SensorLoop
    from agent.core.warmup import warm_up
    from agent.recording.feed import RecordingFeed
    from agent.recording.offline import read_recording_metadata

    meta = read_recording_metadata(path)
    params = PipelineParams.from_table(json.loads(meta["pipeline"]))
    params = replace(params, people=PeopleParams(enabled=people))
    pairs: list[Matched] = []
    # the agent's sensor loop gathers the scans with their poses; the pipeline is timed below
    loop = SensorLoop(SyncParams(reorder=1.0), pairs.append)
    for message in RecordingFeed(path, meta=meta):
        loop.feed(message)
    loop.close()
    pairs = pairs[:limit] if limit else pairs
    warm_up(model, params)
    pipeline = Pipeline(model, params)
    ms = np.empty(len(pairs))
    for i, m in enumerate(pairs):
        t0 = time.perf_counter()
        pipeline.process(m.scan, m.pose)
        ms[i] = (time.perf_counter() - t0) * 1e3
    return ms


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_replay", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--scans", type=int, default=None, help="time only the first N scans per scan (default all)"
    )
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    log = DATA / LOG
    if not log.is_file():
        print(f"{log} is absent: the real-log benchmark needs ../shared/data (or LOCI_DATA)", file=sys.stderr)
        return 2
    from agent.recording.importer import import_log
    from agent.recording.offline import replay_recording
    from knowledge.places.model import PlaceModel, default_model_path

    model = PlaceModel.load(default_model_path())
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "fr079.mcap"
        t0 = time.perf_counter()
        imp = import_log(log, rec, emit=lambda s: None)
        import_s = time.perf_counter() - t0
        replay_recording(rec, model=model)  # compile the kernels, fill the caches
        t0 = time.perf_counter()
        res = replay_recording(rec, model=model)
        replay_s = time.perf_counter() - t0
        stamps_s = _duration(rec)
        on = per_scan(rec, model, True, args.scans)
        off = per_scan(rec, model, False, args.scans)
    budget = 1e3 / RATE_HZ
    timing = {
        name: {
            "p50": round(float(np.percentile(v, 50)), 3),
            "p99": round(float(np.percentile(v, 99)), 3),
            "max": round(float(v.max()), 3),
            "n": int(v.size),
        }
        for name, v in (("people on", on), ("people off", off))
    }
    out: dict[str, Any] = {
        "log": LOG,
        "scans": res.scans,
        "processed": res.processed,
        "import_s": round(import_s, 2),
        "replay_s": round(replay_s, 2),
        "scans_per_s": round(res.processed / replay_s, 1),
        "log_duration_s": round(stamps_s, 1),
        "x_real_time": round(stamps_s / replay_s, 1),
        "per_scan_ms": timing,
        "budget_ms_at_75hz": round(budget, 2),
        "load": round(os.getloadavg()[0], 2),
        "mount": list(imp.mount),
    }
    emit_result(args, out, report)
    return 0


def report(out: dict[str, Any]) -> str:
    """The result as text."""
    timing = out["per_scan_ms"]
    budget = out["budget_ms_at_75hz"]
    p99 = timing["people on"]["p99"]
    lines = [
        f"replay of the real Freiburg 079 log ({out['log']}): {out['scans']:,} scans of 360 beams over 180°",
        f"  import {out['import_s']:.1f} s; replay {out['replay_s']:.1f} s = {out['scans_per_s']:,} scans/s, "
        f"{out['x_real_time']}x the log's own pace ({out['log_duration_s'] / 60:.1f} min recorded)",
        "  Pipeline.process per real scan, ms     p50      p99      max",
    ]
    for name, v in timing.items():
        lines.append(f"    {name:<34} {v['p50']:8.3f} {v['p99']:8.3f} {v['max']:8.3f}")
    lines.append(
        f"  the LMS's period at 75 Hz is {budget:.1f} ms: the p99 scan (people on) takes {p99 / budget:.2f} of it "
        f"({budget / p99:.1f}x inside); load average {out['load']}"
    )
    return "\n".join(lines)


def _duration(path: Path) -> float:
    """Seconds between the recording's first and last scan stamps."""
    from agent.bus.codecs import LASER_SCAN_CODEC
    from agent.recording.replay import McapMessages

    stamps = [LASER_SCAN_CODEC.decode(m.data).stamp for m in McapMessages(path) if m.topic.endswith("/scan")]
    return float(max(stamps) - min(stamps))


if __name__ == "__main__":
    sys.exit(main())
