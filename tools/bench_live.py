"""Benchmark: what the Foxglove live view costs the agent's per-scan path.

A drive along a generated office's corridor and into its rooms, ray cast as the agent's
usual laser sees it (a 180° front laser, 361 beams, 1 cm noise), goes through three
:class:`~agent.core.pipeline.Pipeline` s side by side, scan by scan, in the same process, so
that the shared machine's load falls on all three alike:

* **off**: ``process`` only (the baseline);
* **idle**: ``process`` and the live view's calls (:meth:`LiveView.on_step`, and
  :meth:`LiveView.on_state` when the graph changed) with its server running and no client;
* **watched**: the same with one real client (:mod:`agent.live.probe` in a thread, on
  loopback) subscribed to every channel and reading everything.

Per scan it reports the time of the pipeline and of the live view's calls (p50, p99), and the
whole per-scan path's p99 against the agent's 5 ms target. The occupancy grid is sent at
most once a second (``grid_period``), as in the agent.

    python -m tools.bench_live [--scans N] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.core.pipeline import Pipeline, PipelineParams
from agent.core.warmup import warm_up
from agent.live.probe import connect
from agent.live.server import LiveView
from drivers.messages import LaserScan, Pose2D
from knowledge.metric.raycast import cast
from knowledge.places.model import PlaceModel, default_model_path
from sim.buildings import generate_building

TARGET_MS = 5.0


def drive(n: int, seed: int = 3) -> list[tuple[LaserScan, Pose2D]]:
    """``n`` front-laser scans at 10 Hz along the corridor of a generated office, 0.5 m/s."""
    b = generate_building(seed, furniture=False, layout="straight")
    x0, y0, x1, y1 = b.corridors[0].rects[0]
    y = (y0 + y1) / 2
    xs = x0 + 0.5 + (np.arange(n) * 0.05) % max(0.5, (x1 - x0 - 1.0))
    poses = np.stack([xs, np.full(n, y), np.zeros(n)], axis=1)
    fov = math.pi
    raw = cast(
        b.grid,
        poses,
        n_beams=361,
        max_range=30.0,
        fov=fov,
        angle_min=-fov / 2,
        noise_std=0.01,
        rng=np.random.default_rng(seed),
    )
    t0 = 1.75e9
    out = []
    for i in range(n):
        stamp = t0 + 0.1 * i
        scan = LaserScan(stamp, i, "laser", -fov / 2, fov / 360, 30.0, raw[i])
        out.append((scan, Pose2D(float(xs[i]), float(y), 0.0, stamp=stamp)))
    return out


class Watcher:
    """A real client in another process (as a viewer is): subscribes to everything, decodes
    every message, and reads until its standard input closes; then prints what it got."""

    def __init__(self, url: str) -> None:
        self.received = 0
        self.topics: list[str] = []
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tools.bench_live", "--watch", url],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        )  # fmt: skip

    def wait_ready(self, timeout: float) -> bool:
        assert self.proc.stdout is not None
        return self.proc.stdout.readline().strip() == "subscribed"

    def stop(self) -> None:
        out, _ = self.proc.communicate("", timeout=30)
        got = json.loads(out.strip().splitlines()[-1])
        self.received, self.topics = got["messages"], got["topics"]


async def _watch(url: str) -> None:
    """The watcher process: subscribe to everything, read until stdin closes."""
    probe = await connect(url, timeout=10)
    await probe.subscribe()
    print("subscribed", flush=True)
    done = asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
    count, topics = 0, set()
    while not done.done():
        r = await probe.receive(0.2)
        if r is not None:
            count += 1
            topics.add(r.topic)
    await probe.close()
    print(json.dumps({"messages": count, "topics": sorted(topics)}), flush=True)


def _pct(values: list[float]) -> dict[str, float]:
    s = sorted(values)
    return {
        "p50": round(s[len(s) // 2], 4),
        "p99": round(s[min(len(s) - 1, int(0.99 * len(s)))], 4),
        "mean": round(statistics.fmean(s), 4),
    }


def run(n_scans: int) -> dict[str, Any]:
    model = PlaceModel.load(default_model_path())
    params = PipelineParams()
    warm_up(model, params)
    scans = drive(n_scans)
    pipes = {k: Pipeline(model, params) for k in ("off", "idle", "watched")}
    idle = LiveView("127.0.0.1", 0, name="bench idle")
    watched = LiveView("127.0.0.1", 0, name="bench watched")
    live = {"idle": idle, "watched": watched}
    watcher = Watcher(watched.url)
    if not watcher.wait_ready(15):
        raise RuntimeError("the client did not connect")
    deadline = time.monotonic() + 5
    while not watched.watched and time.monotonic() < deadline:
        time.sleep(0.01)
    pipe_ms: dict[str, list[float]] = {k: [] for k in pipes}
    live_ms: dict[str, list[float]] = {k: [] for k in live}
    try:
        for scan, pose in scans:
            for name, pipe in pipes.items():
                t0 = time.perf_counter()
                result = pipe.process(scan, pose)
                t1 = time.perf_counter()
                pipe_ms[name].append((t1 - t0) * 1e3)
                view = live.get(name)
                if view is not None:
                    view.on_step(result)
                    if result.graph_changed or result.areas_changed:
                        view.on_state(*pipe.messages(result.stamp))
                    live_ms[name].append((time.perf_counter() - t1) * 1e3)
            time.sleep(0.002)  # let the server's threads send
        time.sleep(0.5)
    finally:
        watcher.stop()
        idle.close()
        watched.close()
    total = {k: [p + q for p, q in zip(pipe_ms[k], live_ms[k], strict=True)] for k in live}
    return {
        "scans": n_scans,
        "beams": 361,
        "pipeline_ms": {k: _pct(v) for k, v in pipe_ms.items()},
        "live_view_ms": {k: _pct(v) for k, v in live_ms.items()},
        "per_scan_ms": {k: _pct(v) for k, v in total.items()},
        "target_p99_ms": TARGET_MS,
        "watched_within_target": _pct(total["watched"])["p99"] < TARGET_MS,
        "client": {"messages": watcher.received, "topics": watcher.topics},
        "sent": {k: v for k, v in watched.sent.items() if v},
    }


def report(r: dict[str, Any]) -> str:
    lines = [
        f"{r['scans']} scans of {r['beams']} beams, three pipelines side by side (ms per scan):",
        "",
        "| condition | pipeline p50 | pipeline p99 | live view p50 | live view p99 | per scan p99 |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for k in ("off", "idle", "watched"):
        p = r["pipeline_ms"][k]
        lv = r["live_view_ms"].get(k)
        tot = r["per_scan_ms"].get(k, p)
        lv_cells = f"{lv['p50']:.4f} | {lv['p99']:.4f}" if lv else "— | —"
        lines.append(f"| {k} | {p['p50']:.3f} | {p['p99']:.3f} | {lv_cells} | {tot['p99']:.3f} |")
    lines += [
        "",
        f"target: per scan p99 < {r['target_p99_ms']} ms with one client: "
        + ("met" if r["watched_within_target"] else "MISSED"),
        f"the client received {r['client']['messages']} messages on {', '.join(r['client']['topics'])}",
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_live", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scans", type=int, default=600)
    add_json_option(ap)
    add_json_file_option(ap)
    ap.add_argument("--watch", metavar="URL", help=argparse.SUPPRESS)  # the client process
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.watch:
        asyncio.run(_watch(args.watch))
        return 0
    r = run(args.scans)
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
