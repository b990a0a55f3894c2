"""Benchmark: the running agent — per-scan latency, the highest sustained scan rate, memory over an hour.

All three drive a simulated robot (:class:`~sim.robot.SimRobot`) on a tour of a
generated office and ray cast its 180° front laser (361 beams, SICK LMS 2xx at 0.5°) from
the true pose (:func:`knowledge.metric.raycast.cast`, 1 cm noise); odometry is exact, so a
revisited place is the same place for the navigation graph (drift would make the graph grow
on every lap, which is not what the memory measurement is about).

1. **Latency** (target p99 < 5 ms at 361 beams), one process, real parts only: the bytes of
   the scan's 0xB0 telegram (its last 64 bytes arrive last, as from a serial read) →
   :class:`~drivers.sick.codec.StreamParser` → ranges → :class:`~drivers.messages.LaserScan`
   (as :class:`~drivers.sick.driver.LMS2xx` makes it) → the sensor loop (:class:`~agent.core.sensor_loop.SensorLoop`: the odometry association) →
   :meth:`agent.core.pipeline.Pipeline.process` → the ``loci.place/1`` JSON (validated) → a Zenoh
   publisher; a subscriber in a second Zenoh session (loopback TCP) notes the arrival. One
   scan every ``period`` seconds, each after the previous one arrived, so nothing queues.
   Stages: parse, sync, pipeline, encode, put, delivery; total = telegram → arrival.
2. **Sustained rate**: the real agent (:class:`agent.runtime.Agent`, laser from the bus)
   in this process, fed by a second session (a thread) publishing odometry and pre-encoded
   ``foxglove.LaserScan`` s at increasing rates, ``step`` seconds each; after each step the
   counters say how many were sent, received, dropped (queues, odometry sync) and processed.
   A rate is sustained when nothing was dropped and the agent was done within ``MAX_LAG``
   seconds of the last scan (a short step hides a slowly growing backlog in the 256-sample
   queues otherwise). The highest sustained rate is refined by bisection; the throughput at
   the failing rates (scans processed per second while busy) is the agent's capacity.
3. **Memory**: one simulated hour of touring (laps of the same building) through a
   :class:`~agent.core.pipeline.Pipeline` as fast as the CPU goes, ``memory_rate`` scans per
   simulated second; every simulated minute the traced Python heap (``tracemalloc``, after a
   garbage collection), the RSS, the graph's nodes and edges, the local map's points and the
   label window. Slopes are fitted over the hour and over its second half (after the first
   laps have visited every place).

The baselines, in the same process: the 5 ms target and the LMS's own 37.5 Hz scan rate.

    python -m tools.bench_agent [--only latency|rate|memory] [--quick] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import math
import os
import resource
import sys
import tempfile
import threading
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from agent.bus.bridge import publish_stream
from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC, json_codec
from agent.bus.keys import stream_key
from agent.bus.session import BusConfig, close_session, open_session
from agent.bus.testing import session_pair, settle, wait_until
from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.core.odom_sync import Matched, SyncParams
from agent.core.pipeline import PeopleParams, Pipeline, PipelineParams, place_message
from agent.core.sensor_loop import SensorLoop
from agent.core.warmup import warm_up
from drivers.messages import LaserScan
from drivers.sick import telegrams as tg
from drivers.sick.codec import StreamParser, Telegram
from drivers.sick.constants import MeasuringMode, Units
from knowledge.places.model import PlaceModel, default_model_path
from sim.drives import LMS_HZ, N_BEAMS, DriveScans, make_scan, telegram_values

TARGET_P99_MS = 5.0
#: Bytes of a telegram that arrive in the last serial read.
LAST_READ = 64
ROBOT = "bench"
#: Seconds the agent may still be busy after a step's last scan for the rate to count as sustained.
MAX_LAG = 0.1
#: Seconds between stamping a step's scans and feeding the first of them.
STAMP_LEAD = 0.02
#: Scan rates the sustained-rate sweep tries, scans per second.
RATES = (37.5, 75.0, 150.0, 300.0, 450.0, 600.0, 800.0, 1000.0, 1300.0, 1600.0, 2000.0)


def scan_from_telegram(t: Telegram, stamp: float, seq: int) -> LaserScan:
    """What the LMS driver does with a 0xB0 telegram (``LMS2xx._on_values``)."""
    mv = tg.MeasuredValues.decode(t, realtime_index=False)
    if mv.partial or mv.values.size != N_BEAMS:
        raise ValueError(f"expected {N_BEAMS} values of a complete scan, got {mv.values.size}")
    ranges, _ = tg.values_to_ranges(mv.values, Units.CM, MeasuringMode.R8_80_FIELDS_AB_DAZZLE)
    return make_scan(ranges, stamp, seq)


def load_model() -> PlaceModel:
    model = PlaceModel.load(default_model_path())
    warm_up(model)
    return model


def _percentiles(values_ms: np.ndarray) -> dict[str, float]:
    v = np.asarray(values_ms, dtype=np.float64)
    return {
        "p50": round(float(np.percentile(v, 50)), 3),
        "p99": round(float(np.percentile(v, 99)), 3),
        "max": round(float(v.max()), 3),
        "mean": round(float(v.mean()), 3),
    }


# ---------------------------------------------------------------------------- 1. latency
STAGES = ("parse", "sync", "pipeline", "encode", "put", "delivery")


def bench_latency(
    model: PlaceModel, scans: int = 1500, *, period: float = 0.01, warmup: int = 50
) -> dict[str, Any]:
    """Telegram → published place, per stage (see the module docstring)."""
    drive = DriveScans()
    chunk = drive.take(scans + warmup)
    telegrams = [
        tg.MeasuredValues(telegram_values(chunk.ranges[i]), units=Units.CM).telegram().encode()
        for i in range(len(chunk))
    ]
    pipeline = Pipeline(model)
    parser = StreamParser("reply")
    codec = json_codec("loci.place/1")
    n = len(chunk)
    marks = np.zeros((n, len(STAGES) + 1), dtype=np.int64)
    step_marks: list[int] = []
    cpu = np.zeros(n, dtype=np.int64)
    arrived = np.zeros(n, dtype=np.int64)
    got = threading.Event()
    current = [0]
    key = stream_key(ROBOT, "place")

    def on_place(sample: zenoh.Sample) -> None:
        t = time.perf_counter_ns()
        arrived[current[0]] = t
        got.set()

    lost = 0
    with session_pair() as (agent_side, listener):
        sub = listener.declare_subscriber(key, on_place)
        pub = publish_stream(agent_side, ROBOT, "place")
        settle(agent_side, listener)

        def step(m: Matched) -> None:
            # the agent's step: the pipeline, the place message encoded and put on the bus
            step_marks[:] = [time.perf_counter_ns()]
            result = pipeline.process(m.scan, m.pose)
            step_marks.append(time.perf_counter_ns())
            data = codec.encode(place_message(result))
            step_marks.append(time.perf_counter_ns())
            pub.put_bytes(data)
            step_marks.append(time.perf_counter_ns())

        loop = SensorLoop(SyncParams(), step)
        try:
            for i in range(n):
                start = time.perf_counter()
                raw = telegrams[i]
                parser.feed(raw[:-LAST_READ])  # the telegram's head is already in
                current[0] = i
                got.clear()
                # the scan arrives as it is taken: its stamp is simulated time (epoch-based, running
                # ahead of the wall clock), and OdomSync refuses stamps too far ahead of `now`
                now = float(chunk.stamps[i])
                c0 = time.thread_time_ns()
                t0 = time.perf_counter_ns()
                events = parser.feed(raw[-LAST_READ:])
                t = next(e for e in events if isinstance(e, Telegram))
                scan = scan_from_telegram(t, float(chunk.stamps[i]), i + 1)
                t1 = time.perf_counter_ns()
                loop.odom(chunk.odom[i], now)
                loop.scan(scan, now)  # the sensor loop's association, then its step
                t2, t3, t4, t5 = step_marks
                cpu[i] = time.thread_time_ns() - c0
                marks[i] = (t0, t1, t2, t3, t4, t5, 0)
                if not got.wait(1.0):
                    lost += 1
                time.sleep(max(0.0, start + period - time.perf_counter()))
        finally:
            pub.close()
            sub.undeclare()
    # the same scans through a pipeline without people: what detecting them costs per scan
    bare = Pipeline(model, PipelineParams(people=PeopleParams(enabled=False)))
    bare_ns = np.zeros(n, dtype=np.int64)
    for i in range(n):
        scan = scan_from_telegram(
            next(e for e in StreamParser("reply").feed(telegrams[i]) if isinstance(e, Telegram)),
            float(chunk.stamps[i]),
            i + 1,
        )
        t0 = time.perf_counter_ns()
        bare.process(scan, chunk.odom[i])
        bare_ns[i] = time.perf_counter_ns() - t0
    keep = slice(warmup, n)
    ok = arrived[keep] > 0
    m = marks[keep][ok]
    a = arrived[keep][ok]
    stage_ns = {
        "parse": m[:, 1] - m[:, 0],
        "sync": m[:, 2] - m[:, 1],
        "pipeline": m[:, 3] - m[:, 2],
        "encode": m[:, 4] - m[:, 3],
        "put": m[:, 5] - m[:, 4],
        "delivery": a - m[:, 5],
    }
    total = _percentiles((a - m[:, 0]) / 1e6)
    return {
        "load_average": [round(v, 2) for v in os.getloadavg()],
        "scans": int(ok.sum()),
        "lost": lost,
        "beams": N_BEAMS,
        "period_ms": period * 1e3,
        "nodes": len(pipeline.graph),
        "total_ms": total,
        "stages_ms": {k: _percentiles(v / 1e6) for k, v in stage_ns.items()},
        "pipeline_without_people_ms": _percentiles(bare_ns[keep] / 1e6),
        "cpu_parse_to_put_ms": _percentiles(cpu[keep][ok] / 1e6),
        "target_p99_ms": TARGET_P99_MS,
        "p99_vs_target": round(TARGET_P99_MS / total["p99"], 1),
        "p99_vs_scan_period": round((1e3 / LMS_HZ) / total["p99"], 1),
    }


# ---------------------------------------------------------------------------- 2. sustained rate
@dataclass
class Counters:
    sent: int = 0
    received: int = 0
    dropped: int = 0
    processed: int = 0


class RateProbe:
    """Feeds the agent over the bus and reads its counters (runs in a thread beside the agent)."""

    def __init__(self, agent: Any, drive: DriveScans) -> None:
        self.agent = agent
        self.drive = drive
        self.sent = 0
        self._t0 = 0.0  # the stamp of the next feed's first scan (wall clock)
        self.session = open_session(BusConfig(listen=(), connect=tuple(agent.endpoints)))
        self.pub_scan = publish_stream(self.session, ROBOT, "scan")
        self.pub_odom = publish_stream(self.session, ROBOT, "odom")

    def close(self) -> None:
        self.pub_scan.close()
        self.pub_odom.close()
        close_session(self.session)

    def counters(self) -> Counters:
        snap = self.agent.stats.snapshot()
        s = self.agent.sync.stats
        scan, odom = snap.get("scan", {}), snap.get("odom", {})
        dropped = scan.get("dropped", 0) + odom.get("dropped", 0) + s.dropped
        processed = self.agent.pipeline.scans if self.agent.pipeline is not None else 0
        return Counters(self.sent, scan.get("received", 0), dropped, processed)

    def encode(self, n: int, rate: float) -> list[tuple[bytes, bytes]]:
        """The next ``n`` scans and their odometry, stamped as a laser running at ``rate``
        from the moment :meth:`feed` starts: stamps follow the wall clock of the feed, as a
        real sensor's do (scans stamped ahead of their arrival are refused by the agent's
        odometry sync, ``future_stamp``, so the drive's own 37.5 Hz stamps cannot be sent
        faster than that)."""
        chunk = self.drive.take(n)
        self._t0 = time.time() + STAMP_LEAD
        out = []
        for i in range(n):
            stamp = self._t0 + i / rate
            scan = replace(self.drive.scan(chunk, i), stamp=stamp)
            odom = replace(chunk.odom[i], stamp=stamp)
            out.append((POSE_CODEC.encode(odom), LASER_SCAN_CODEC.encode(scan)))
        return out

    def feed(self, payloads: list[tuple[bytes, bytes]], rate: float) -> float:
        """Publish at ``rate`` scans per second, the first when its stamp comes (see
        :meth:`encode`); returns the rate achieved."""
        wait = self._t0 - time.time()
        if wait > 0:
            time.sleep(wait)
        t0 = time.perf_counter()
        for i, (odom, scan) in enumerate(payloads):
            delay = t0 + i / rate - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            self.pub_odom.put_bytes(odom)
            self.pub_scan.put_bytes(scan)
            self.sent += 1
        elapsed = time.perf_counter() - t0
        return len(payloads) / elapsed if elapsed > 0 else math.inf

    def settle(self, timeout: float = 10.0) -> float:
        """Wait until the agent stops processing (or has processed all); returns when it last moved."""
        last = self.counters().processed
        moved = time.perf_counter()
        deadline = moved + timeout
        while time.perf_counter() < deadline:
            time.sleep(0.005)
            c = self.counters()
            if c.processed != last:
                last, moved = c.processed, time.perf_counter()
            elif c.processed >= self.sent or time.perf_counter() - moved > 0.6:
                break
        return moved

    def step(self, rate: float, seconds: float) -> dict[str, Any]:
        payloads = self.encode(max(10, round(rate * seconds)), rate)
        before = self.counters()
        t0 = time.perf_counter()
        achieved = self.feed(payloads, rate)
        fed = time.perf_counter()
        moved = self.settle()
        after = self.counters()
        d = {k: getattr(after, k) - getattr(before, k) for k in ("sent", "received", "dropped", "processed")}
        busy = max(moved - t0, 1e-9)
        lag = max(0.0, moved - fed)
        # the agent's own counters decide, and it must keep pace (a backlog still growing when
        # the step ends would overflow its queue in a longer one); samples Zenoh lost on the
        # way are reported apart
        ok = d["dropped"] == 0 and d["processed"] == d["received"] and lag <= MAX_LAG
        return {
            "rate": round(rate, 1),
            "achieved": round(achieved, 1),
            **d,
            "lost_in_transit": d["sent"] - d["received"],
            "throughput": round(d["processed"] / busy, 1),
            "lag_s": round(lag, 3),
            "ok": ok,
        }


def bench_rate(
    model: PlaceModel,
    *,
    rates: Sequence[float] = RATES,
    step: float = 4.0,
    refine: int = 2,
) -> dict[str, Any]:
    """The highest scan rate the agent sustains without losing a scan (see the module docstring)."""
    from agent.config import load_config
    from agent.runtime import Agent

    result: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="loci-bench-") as tmp:
        config = load_config(
            table={
                "robot": {"name": ROBOT},
                "bus": {"listen": ["tcp/127.0.0.1:0"]},
                "laser": {"source": "bus"},
                "state": {"dir": tmp, "resume": False, "save_interval": 5.0},
            },
            env={},
        )
        ready = threading.Event()
        agent = Agent(config, model=model, on_ready=lambda _: ready.set())

        def sweep(stop: asyncio.Event, loop: asyncio.AbstractEventLoop) -> None:
            try:
                if not ready.wait(60.0):
                    raise RuntimeError("the agent did not start within 60 s")
                probe = RateProbe(agent, DriveScans(seed=1))
                try:
                    result.update(_sweep(probe, rates, step, refine))
                finally:
                    probe.close()
            finally:
                loop.call_soon_threadsafe(stop.set)

        async def main() -> Any:
            stop = asyncio.Event()
            feeder = asyncio.create_task(asyncio.to_thread(sweep, stop, asyncio.get_running_loop()))
            report = await agent.run(stop)
            await feeder
            return report

        report = asyncio.run(main())
        result["agent"] = {
            "scans_processed": report.scans_processed,
            "nodes": report.nodes,
            "drops": report.drops,
        }
    return result


def _sweep(probe: RateProbe, rates: Sequence[float], step: float, refine: int) -> dict[str, Any]:
    # a slow start so the subscriptions are in place before anything counts
    probe.feed(probe.encode(40, 20.0), 20.0)
    if not wait_until(lambda: probe.counters().processed >= 20, 10.0):
        raise RuntimeError("the agent processes no scans from the bus")
    probe.settle()
    steps: list[dict[str, Any]] = []
    good: float | None = None
    bad: float | None = None
    for rate in rates:
        s = probe.step(rate, step)
        steps.append(s)
        if s["ok"]:
            good = rate
        else:
            bad = rate
            break
        if s["achieved"] < 0.9 * rate:
            break  # the feeder itself cannot go faster
    if good is not None and bad is not None:
        for _ in range(refine):
            mid = 0.5 * (good + bad)
            s = probe.step(mid, step)
            steps.append(s)
            good, bad = (mid, bad) if s["ok"] else (good, mid)
    failing = [s for s in steps if not s["ok"]]
    return {
        "step_s": step,
        "steps": steps,
        "sustained_hz": good,
        "first_failing_hz": bad,
        "capacity_hz": max((s["throughput"] for s in failing), default=None),
        "sustained_vs_lms": round(good / LMS_HZ, 1) if good else None,
    }


# ---------------------------------------------------------------------------- 3. memory
def rss_mb() -> float:
    """The resident set size now, MiB (peak RSS where /proc is missing)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:  # pragma: no cover - not Linux
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _slope_per_hour(minutes: np.ndarray, values: np.ndarray) -> float:
    if len(minutes) < 2:
        return 0.0
    return float(np.polyfit(minutes, values, 1)[0] * 60.0)


def bench_memory(
    model: PlaceModel,
    *,
    seconds: float = 3600.0,
    scan_hz: float = 10.0,
    trace_minutes: int = 20,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Simulated driving through the pipeline, memory every simulated minute.

    ``tracemalloc`` (which triples the time per scan) runs over the last ``trace_minutes``
    minutes: the heap it reports is what was allocated since and is still alive, which
    levels off at the working set when nothing leaks and keeps rising when something does.
    RSS, the count of Python objects and the structures' sizes are sampled all along.
    """
    drive = DriveScans(building=5, scan_hz=scan_hz, seed=2)
    pipeline = Pipeline(model)
    per_minute = max(1, round(60.0 * scan_hz))
    minutes = max(1, round(seconds / 60.0))
    trace_from = max(0, minutes - max(0, trace_minutes)) if trace_minutes > 0 else minutes + 1
    rows: list[dict[str, Any]] = []
    t_start = time.perf_counter()
    try:
        rows.append(_memory_row(0, pipeline))
        for minute in range(1, minutes + 1):
            if minute - 1 == trace_from:
                tracemalloc.start()
            chunk = drive.take(per_minute)
            for i in range(len(chunk)):
                pipeline.process(drive.scan(chunk, i), chunk.odom[i])
            del chunk
            rows.append(_memory_row(minute, pipeline))
            if progress is not None and minute % 10 == 0:
                r = rows[-1]
                progress(
                    f"minute {minute}: {r['nodes']} nodes, RSS {r['rss_mb']:.1f} MiB, {r['objects']} objects"
                )
    finally:
        tracemalloc.stop()
    wall = time.perf_counter() - t_start
    m = np.array([r["minute"] for r in rows], dtype=np.float64)
    second_half = m >= m[-1] / 2
    out: dict[str, Any] = {
        "simulated_s": minutes * 60,
        "scans": pipeline.scans,
        "scan_hz": scan_hz,
        "wall_s": round(wall, 1),
        "laps": round(minutes * 60 / drive.lap_seconds, 1),
        "collisions": drive.robot.base.collisions,
        "traced_from_minute": trace_from if trace_from <= minutes else None,
        "curve": rows,
    }
    for name in ("rss_mb", "objects", "nodes", "local_map_points"):
        v = np.array([r[name] for r in rows], dtype=np.float64)
        out[f"{name}_per_h"] = round(_slope_per_hour(m[1:], v[1:]), 3)
        out[f"{name}_per_h_second_half"] = round(_slope_per_hour(m[second_half], v[second_half]), 3)
    traced = [r for r in rows if r["heap_mb"] is not None]
    settled = traced[3:] if len(traced) > 5 else traced
    out["heap_mb_per_h"] = round(
        _slope_per_hour(
            np.array([r["minute"] for r in settled], float), np.array([r["heap_mb"] for r in settled])
        ),
        3,
    )
    out["heap_mb_range"] = (
        [min(r["heap_mb"] for r in settled), max(r["heap_mb"] for r in settled)] if settled else None
    )
    half = rows[int(np.flatnonzero(second_half)[0])]
    out["nodes_second_half"] = [half["nodes"], rows[-1]["nodes"]]
    out["bounded"] = {
        "local_map_points_max": max(r["local_map_points"] for r in rows),
        "local_map_limit": pipeline.params.local_map.max_points,
        "label_window_max": max(r["label_window"] for r in rows),
        "label_window_limit": pipeline.params.graph.window,
    }
    return out


def _memory_row(minute: int, pipeline: Pipeline) -> dict[str, Any]:
    gc.collect()
    tracing = tracemalloc.is_tracing()
    return {
        "minute": minute,
        "rss_mb": round(rss_mb(), 2),
        "heap_mb": round(tracemalloc.get_traced_memory()[0] / 2**20, 3) if tracing else None,
        "objects": len(gc.get_objects()),
        "nodes": len(pipeline.graph),
        "edges": sum(1 for _ in pipeline.graph.edges()),
        "areas": len(pipeline.areas.areas),
        "local_map_points": len(pipeline.local_map),
        "label_window": len(pipeline.graph.recent),
    }


# ---------------------------------------------------------------------------- driver
def run(
    only: Sequence[str] = ("latency", "rate", "memory"),
    *,
    quick: bool = False,
    scans: int = 1500,
    memory_seconds: float = 3600.0,
    memory_rate: float = 10.0,
    trace_minutes: int = 20,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the chosen measurements; ``quick`` shrinks them (a smoke run, not a measurement)."""
    say = progress or (lambda _msg: None)
    say("loading the place model and compiling the kernels")
    model = load_model()
    out: dict[str, Any] = {"benchmark": "agent", "beams": N_BEAMS}
    if "latency" in only:
        say("latency: telegram → published place")
        out["latency"] = bench_latency(model, 200 if quick else scans)
    if "rate" in only:
        say("rate: feeding the agent over the bus at increasing rates")
        if quick:
            out["rate"] = bench_rate(model, rates=(37.5, 150.0), step=0.5, refine=0)
        else:
            out["rate"] = bench_rate(model)
    if "memory" in only:
        say("memory: a simulated hour of touring")
        out["memory"] = bench_memory(
            model,
            seconds=300.0 if quick else memory_seconds,
            scan_hz=memory_rate,
            trace_minutes=3 if quick else trace_minutes,
            progress=say,
        )
    return out


def report(r: dict[str, Any]) -> str:
    """The results as text for people."""
    lines = [
        f"Agent per scan, {r['beams']} beams (SICK LMS 2xx 180°/0.5°), a simulated robot touring a generated office"
    ]
    if "latency" in r:
        lat = r["latency"]
        t = lat["total_ms"]
        lines += [
            "",
            f"Latency telegram → place received by a second Zenoh session ({lat['scans']} scans, one per "
            f"{lat['period_ms']:.0f} ms, {lat['nodes']} graph nodes at the end, {lat['lost']} lost):",
            f"  total   p50 {t['p50']:6.3f} ms   p99 {t['p99']:6.3f} ms   max {t['max']:7.3f} ms   "
            f"(target p99 < {lat['target_p99_ms']} ms: {lat['p99_vs_target']}x headroom; "
            f"{lat['p99_vs_scan_period']}x inside the 26.7 ms scan period)",
        ]
        for name in STAGES:
            s = lat["stages_ms"][name]
            lines.append(
                f"  {name:9s} p50 {s['p50']:6.3f} ms   p99 {s['p99']:6.3f} ms   mean {s['mean']:6.3f} ms"
            )
        if "pipeline_without_people_ms" in lat:
            b, p = lat["pipeline_without_people_ms"], lat["stages_ms"]["pipeline"]
            lines.append(
                f"  the pipeline without people detection: p50 {b['p50']:6.3f} ms   p99 {b['p99']:6.3f} ms "
                f"(people add {p['p50'] - b['p50']:.3f} ms at p50)"
            )
        c = lat["cpu_parse_to_put_ms"]
        lines.append(
            f"  CPU time of this thread, parse → put: p50 {c['p50']:.3f} ms, p99 {c['p99']:.3f} ms "
            f"(wall minus CPU is waiting for a core; load average {lat['load_average']} on {os.cpu_count()} cores)"
        )
    if "rate" in r:
        rate = r["rate"]
        lines += [
            "",
            f"Sustained scan rate, the agent fed over the bus ({rate['step_s']} s per rate):",
            "  rate Hz   achieved   sent  received  dropped  processed  throughput Hz  lag s",
        ]
        for s in rate["steps"]:
            lines.append(
                f"  {s['rate']:7.1f}  {s['achieved']:9.1f}  {s['sent']:5d}  {s['received']:8d}  {s['dropped']:7d}  "
                f"{s['processed']:9d}  {s['throughput']:13.1f}  {s['lag_s']:5.2f}  {'ok' if s['ok'] else 'no'}"
            )
        transit = sum(s["lost_in_transit"] for s in rate["steps"])
        lines.append(
            f"  (dropped: the agent's counters — its queues and the odometry sync; lag: how long it was still "
            f"busy after the last scan of the step, at most {MAX_LAG} s to count as keeping pace; "
            f"{transit} samples were lost by Zenoh on the way, not counted against the agent)"
        )
        lines.append(
            f"  sustained without loss: {rate['sustained_hz']} Hz ({rate['sustained_vs_lms']}x the LMS's 37.5 Hz); "
            f"first loss at {rate['first_failing_hz']} Hz; capacity under overload {rate['capacity_hz']} Hz"
        )
    if "memory" in r:
        mem = r["memory"]
        traced = mem["traced_from_minute"]
        lines += [
            "",
            f"Memory over {mem['simulated_s'] / 60:.0f} simulated minutes ({mem['scans']} scans at {mem['scan_hz']} Hz, "
            f"{mem['laps']} laps, {mem['collisions']} collisions, {mem['wall_s']} s wall"
            f"{f'; tracemalloc from minute {traced}' if traced is not None else ''}):",
            "  minute   RSS MiB   heap MiB   objects   nodes  edges  areas  local map  window",
        ]
        curve = mem["curve"]
        every = max(1, len(curve) // 12)
        for row in curve:
            if row["minute"] % every and row is not curve[-1] and row["heap_mb"] is None:
                continue
            heap = "-" if row["heap_mb"] is None else f"{row['heap_mb']:.3f}"
            lines.append(
                f"  {row['minute']:6d}  {row['rss_mb']:8.1f}  {heap:>9s}  {row['objects']:8d}  {row['nodes']:6d}  "
                f"{row['edges']:5d}  {row['areas']:5d}  {row['local_map_points']:9d}  {row['label_window']:6d}"
            )
        b = mem["bounded"]
        lines += [
            f"  per hour, fitted over the hour (second half): RSS {mem['rss_mb_per_h']:+.2f} "
            f"({mem['rss_mb_per_h_second_half']:+.2f}) MiB, objects {mem['objects_per_h']:+.0f} "
            f"({mem['objects_per_h_second_half']:+.0f}), nodes {mem['nodes_per_h']:+.1f} "
            f"({mem['nodes_per_h_second_half']:+.1f})",
            f"  traced heap (allocated since tracing began, still alive): {mem['heap_mb_range']} MiB, "
            f"{mem['heap_mb_per_h']:+.3f} MiB per hour",
            f"  bounded: local map ≤ {b['local_map_points_max']} points (limit {b['local_map_limit']}), "
            f"label window ≤ {b['label_window_max']} (limit {b['label_window_limit']}); "
            f"nodes in the second half {mem['nodes_second_half'][0]} → {mem['nodes_second_half'][1]}",
        ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_agent", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--only",
        action="append",
        choices=("latency", "rate", "memory"),
        help="run only this part (repeatable)",
    )
    ap.add_argument("--quick", action="store_true", help="a short smoke run (not a measurement)")
    ap.add_argument("--scans", type=int, default=1500, help="scans timed for the latency (default: 1500)")
    ap.add_argument(
        "--memory-seconds", type=float, default=3600.0, help="simulated seconds of driving (default: 3600)"
    )
    ap.add_argument(
        "--memory-rate",
        type=float,
        default=10.0,
        help="scans per simulated second in the memory run (default: 10)",
    )
    ap.add_argument(
        "--trace-minutes",
        type=int,
        default=20,
        help="memory: tracemalloc over the last N simulated minutes (0: off; it triples the time per scan)",
    )
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run(
        tuple(args.only or ("latency", "rate", "memory")),
        quick=args.quick,
        scans=args.scans,
        memory_seconds=args.memory_seconds,
        memory_rate=args.memory_rate,
        trace_minutes=args.trace_minutes,
        progress=lambda msg: print(f"[bench_agent] {msg}", file=sys.stderr, flush=True),
    )
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
