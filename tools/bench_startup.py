"""Benchmark: how long a restarted agent takes to answer, against the size of its saved map.

``loci run`` is started on a state folder holding a saved map (``navgraph.json``) of N place
nodes (a robot driven up and down the 100 m rows of a large building, passing a doorway every
20 m; the areas are what the area map makes of them), with its conceptual map (the areas synced into ``concepts.sqlite3`` by
a first start, not timed). Measured from the spawn of the process, as a client sees it
(``state/graph`` asked every 50 ms): **session** the first answer of any kind (the agent says
"starting" from then on), **answering** the first answer with the map. The baseline is the
same start on an empty state folder, in the same run: the ratio says what the map adds.

    python -m tools.bench_startup [--nodes 500,2000,5000] [--runs 3] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import math
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from tools.crash import agent_config

REPO = Path(__file__).resolve().parents[1]
ROBOT = "startbot"


def saved_map(nodes: int, state: Path) -> tuple[int, int]:
    """Write ``state/navgraph.json`` with about ``nodes`` place nodes; returns (nodes, areas)."""
    from knowledge.navigation.doorways import Doorway
    from knowledge.navigation.graph import GraphParams, NavigationGraph
    from knowledge.topology import persistence
    from knowledge.topology.areas import AreaMap

    g = NavigationGraph(GraphParams(node_distance=1.0))
    row_len, row_gap = 100.0, 3.0
    rows = max(1, math.ceil(nodes / row_len))
    y = 0.0
    for r in range(rows):
        x0, x1 = (0.0, row_len) if r % 2 == 0 else (row_len, 0.0)
        heading = 0.0 if x1 > x0 else math.pi
        doors = {round(x) for x in np.arange(20.0, row_len, 20.0)}
        for x in np.arange(x0, x1, 0.05 if x1 > x0 else -0.05):
            door = Doorway((float(x), y), 0.9, heading, 0.0) if round(float(x), 2) in doors else None
            g.update((float(x), y, heading), "corridor", door, in_opening=door is not None)
        for dy in np.arange(0.0, row_gap, 0.05):  # to the next row
            g.update((x1, y + float(dy), math.pi / 2), "corridor")
        y += row_gap
    areas = AreaMap()
    areas.update(g)
    state.mkdir(parents=True, exist_ok=True)
    persistence.save(state / "navgraph.json", g, areas, meta={"robot": ROBOT})
    return len(g), len(areas.areas)


def start_once(config: Path, session: Any) -> dict[str, float]:
    """Spawn ``loci run``, time its first answer and its first answer with the map, stop it."""
    from agent.bus.queryable import query_state

    t0 = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-m", "agent.cli", "run", "--config", str(config)],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    first: float | None = None
    try:
        while time.monotonic() - t0 < 300:
            if proc.poll() is not None:
                raise RuntimeError(f"loci run exited: {proc.stderr.read() if proc.stderr else ''}")
            for r in query_state(session, f"loci/{ROBOT}/state/graph", timeout=1.0):
                now = time.monotonic() - t0
                first = now if first is None else first
                if r.value is not None:
                    return {"session_s": first, "answering_s": now, "nodes": len(r.value["nodes"])}
            time.sleep(0.05)
        raise RuntimeError("loci run did not answer within 300 s")
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def measure(sizes: list[int], runs: int) -> dict[str, Any]:
    from agent.bus.session import BusConfig, bus_session, listening_endpoints

    rows: list[dict[str, Any]] = []
    with bus_session(BusConfig()) as session, tempfile.TemporaryDirectory() as tmp:
        (endpoint,) = listening_endpoints(session)
        for size in [0, *sizes]:
            work = Path(tmp) / f"map-{size}"
            work.mkdir()
            nodes, areas = saved_map(size, work / "state") if size else (0, 0)
            config = agent_config(work, endpoint, ROBOT)
            start_once(config, session)  # the concepts take the areas in; the caches are warm
            times = [start_once(config, session) for _ in range(runs)]
            rows.append(
                {
                    "nodes": nodes,
                    "areas": areas,
                    "navgraph_kb": round((work / "state" / "navgraph.json").stat().st_size / 1024, 1)
                    if size
                    else 0.0,
                    "session_s": round(statistics.median(t["session_s"] for t in times), 2),
                    "answering_s": round(statistics.median(t["answering_s"] for t in times), 2),
                    "answering_max_s": round(max(t["answering_s"] for t in times), 2),
                    "answered_nodes": times[-1]["nodes"],
                }
            )
    base = rows[0]["answering_s"]
    for r in rows:
        r["x_empty"] = round(r["answering_s"] / base, 2)
    return {"runs": runs, "rows": rows}


def report(out: dict[str, Any]) -> str:
    lines = [
        f"loci run restarted on a saved map; median of {out['runs']} starts, seconds from the spawn",
        "  nodes  areas  navgraph.json  first answer  answering with the map (max)  x empty",
    ]
    for r in out["rows"]:
        lines.append(
            f"  {r['nodes']:5d}  {r['areas']:5d}  {r['navgraph_kb']:9.1f} kB  {r['session_s']:10.2f} s  "
            f"{r['answering_s']:14.2f} s ({r['answering_max_s']:.2f})  {r['x_empty']:13.2f}"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_startup", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--nodes", default="500,2000,5000", help="saved map sizes, place nodes (default 500,2000,5000)"
    )
    ap.add_argument("--runs", type=int, default=3, help="timed starts per size (default 3)")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    sizes = [int(x) for x in args.nodes.split(",") if x]
    out = measure(sizes, args.runs)
    emit_result(args, out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
