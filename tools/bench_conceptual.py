"""Benchmark: conceptual-map latencies through the service (owner thread, debounced HermiT).

1. **inference latency** — from ``add_object`` (a couch seen in a new room, submitted to the
   service) until ``snapshot()`` shows the area as a LivingRoom: debounce + one HermiT run
   (JVM start included). Target ≤ 2 s.
2. **query latency** — answering "where is the television" / "the room with the couch" from
   the cached state (``snapshot()`` + ``resolve()``), never touching Java. Target ≤ 100 ms.
3. **reasoning alone** — ``ConceptualMap.reason()`` on the same map, on the owner thread.

The map grows as the benchmark runs (one room with objects per repetition, plus ``--areas``
filler areas with objects), so the later repetitions reason over a building-sized map.

    python -m tools.bench_conceptual [--repeat 15] [--areas 30] [--debounce 0.2] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.conceptual_service import ConceptualService
from knowledge.conceptual import ConceptualMap

INFERENCE_TARGET_S = 2.0
QUERY_TARGET_S = 0.1
_FILLER = ("desk", "monitor", "bucket", "table", "fridge", "bookcase", "chair", "plant")


def _stats(x: list[float], target: float) -> dict[str, float]:
    a = np.asarray(x)
    p50, p99 = float(np.percentile(a, 50)), float(np.percentile(a, 99))
    return {
        "p50_ms": round(p50 * 1e3, 3),
        "p99_ms": round(p99 * 1e3, 3),
        "max_ms": round(float(a.max()) * 1e3, 3),
        "target_ms": round(target * 1e3, 1),
        "target_ratio": round(target / p99, 2),  # > 1: p99 within the target
    }


async def _run(repeat: int, areas: int, debounce: float, queries: int) -> dict[str, Any]:
    service = ConceptualService(None, debounce=debounce)
    t0 = time.perf_counter()
    await service.start()
    start_s = time.perf_counter() - t0
    try:

        def fill(m: ConceptualMap) -> None:
            for a in range(1000, 1000 + areas):
                m.set_area(a, "corridor" if a % 4 == 0 else "room")
                m.add_object(f"{_FILLER[a % len(_FILLER)]} {a}", _FILLER[a % len(_FILLER)], a, node=a)

        await service.submit(fill)
        await service.flush()
        inference: list[float] = []
        for i in range(1, repeat + 1):
            await service.submit(partial(ConceptualMap.set_area, area=i, cls="room"))
            await service.flush()
            t0 = time.perf_counter()
            await service.submit(
                partial(ConceptualMap.add_object, name=f"couch {i}", kind="couch", area=i, node=i)
            )
            while "LivingRoom" not in service.snapshot()["areas"][str(i)]["types"]:
                await asyncio.sleep(0.002)
            inference.append(time.perf_counter() - t0)
        await service.submit(lambda m: m.add_object("television", "tv", 1, node=1))
        await service.flush()
        query: list[float] = []
        words = ("television", "the room with the couch", "living room", "kitchen", "charging station")
        for k in range(queries):
            t0 = time.perf_counter()
            snap = service.snapshot()
            r = service.resolve(words[k % len(words)])
            assert snap["version"] >= 0 and r.words
            query.append(time.perf_counter() - t0)
        reason_s: list[float] = []
        for i in range(min(repeat, 10)):
            await service.submit(
                partial(ConceptualMap.assert_name, area=1, name=f"name {i}", speaker="bench")
            )

            def timed_reason(m: ConceptualMap) -> float:
                t = time.perf_counter()
                m.reason()
                return time.perf_counter() - t

            reason_s.append(await service.submit(timed_reason))
        snap = service.snapshot()
        return {
            "benchmark": "conceptual",
            "repeat": repeat,
            "debounce_s": debounce,
            "areas": len(snap["areas"]),
            "objects": len(snap["objects"]),
            "start_s": round(start_s, 3),
            "inference": _stats(inference, INFERENCE_TARGET_S),
            "query": _stats(query, QUERY_TARGET_S),
            "reason": _stats(reason_s, INFERENCE_TARGET_S),
            "reasonings": service.reasonings,
        }
    finally:
        await service.close()


def run(repeat: int = 15, areas: int = 30, debounce: float = 0.2, queries: int = 200) -> dict[str, Any]:
    """Run the benchmark; returns a JSON-ready dict of latencies (ms) and ratios against targets."""
    return asyncio.run(_run(repeat, areas, debounce, queries))


def report(r: dict[str, Any]) -> str:
    """The result as text."""
    lines = [
        f"Conceptual map: {r['areas']} areas, {r['objects']} objects, debounce {r['debounce_s']} s",
        f"  service start (Java check, ontology load): {r['start_s']} s",
    ]
    for key, what in (
        ("inference", "add_object → LivingRoom in snapshot()"),
        ("query", "snapshot() + resolve() from the cache"),
        ("reason", "reason() alone (one HermiT run)"),
    ):
        s = r[key]
        lines.append(
            f"  {what}: p50 {s['p50_ms']} ms, p99 {s['p99_ms']} ms, max {s['max_ms']} ms; "
            f"target {s['target_ms']} ms → ratio {s['target_ratio']}"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench_conceptual", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--repeat", type=int, default=15, help="inference measurements (default: 15)")
    ap.add_argument("--areas", type=int, default=30, help="filler areas with an object each (default: 30)")
    ap.add_argument("--debounce", type=float, default=0.2, help="service debounce in seconds (default: 0.2)")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run(args.repeat, args.areas, args.debounce)
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
