"""The same result at any speed: one recording through the agent under different timing.

:func:`run_conditions` takes the first seconds of a recording through

* ``fast``: ``loci replay`` as fast as possible (the reference);
* ``realtime``: ``loci replay --realtime``;
* ``pinned``: ``loci replay --realtime`` on one core (``taskset -c 0``) beside a busy loop on it;
* ``live``: the live agent, ``loci run --play`` (its tasks, its tracker thread, the bus), on
  the same busy core;

the last three at once (with one busy loop on core 0), each with the same configuration, and
returns what each made: every scan's pose and label, the navigation graph and the areas.
:func:`differences` compares them with the reference.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agent.recording.replay import McapMessages

CONDITIONS = ("fast", "realtime", "pinned", "live")


@dataclass
class Outcome:
    """What one condition made: ``poses`` stamp → (x, y, theta, label), the graph's nodes and
    edges and the areas (from the saved ``loci.navgraph/1``), and the run's wall time."""

    poses: dict[float, tuple[float, float, float, str]]
    nodes: list[tuple[Any, ...]]
    edges: list[tuple[int, int]]
    areas: list[tuple[Any, ...]]
    seconds: float


def _graph(path: Path) -> tuple[list[tuple[Any, ...]], list[tuple[int, int]], list[tuple[Any, ...]]]:
    doc = json.loads(path.read_text(encoding="utf-8"))
    nodes = sorted(
        (n["id"], round(n["x"], 6), round(n["y"], 6), n["kind"], n.get("label")) for n in doc["nodes"]
    )
    edges = sorted((min(e["source"], e["target"]), max(e["source"], e["target"])) for e in doc["edges"])
    areas = sorted(
        (a["id"], a.get("label"), tuple(sorted(a["nodes"])))
        for a in (doc.get("areas") or {}).get("areas", [])
    )
    return nodes, edges, areas


def _places_jsonl(path: Path) -> dict[float, tuple[float, float, float, str]]:
    out = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        d = json.loads(line)
        p = d["pose"]
        out[round(d["stamp"], 6)] = (p["x"], p["y"], p["theta"], d["label"])
    return out


def _places_mcap(path: Path, robot: str) -> dict[float, tuple[float, float, float, str]]:
    out = {}
    for m in McapMessages(path, topics={f"loci/{robot}/place"}):
        d = json.loads(m.data)
        p = d["pose"]
        out[round(d["stamp"], 6)] = (p["x"], p["y"], p["theta"], d["label"])
    return out


def write_config(folder: Path, robot: str, extra: str = "") -> Path:
    """A configuration for the runs: the robot's name, a free port, a fresh state, ``extra``."""
    path = folder / "agent.toml"
    path.write_text(
        f'[robot]\nname = "{robot}"\n\n[bus]\nlisten = ["tcp/127.0.0.1:0"]\n\n'
        f'[state]\ndir = "{folder / "state"}"\nresume = false\n\n[conceptual]\nenabled = false\n\n{extra}',
        encoding="utf-8",
    )
    return path


def _loci(*args: str) -> list[str]:
    return [sys.executable, "-m", "agent.cli", *args]


def run_conditions(
    recording: Path, robot: str, folder: Path, seconds: float, extra: str = ""
) -> dict[str, Outcome]:
    """The recording's first ``seconds`` under each of :data:`CONDITIONS` (module docstring)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    out: dict[str, Outcome] = {}
    dirs = {c: folder / c for c in CONDITIONS}
    configs = {}
    for c, d in dirs.items():
        d.mkdir(parents=True, exist_ok=True)
        configs[c] = write_config(d, robot, extra)

    def replay(c: str, *more: str) -> list[str]:
        d = dirs[c]
        return _loci(
            "replay", str(recording), "--config", str(configs[c]), "--duration", f"{seconds:g}",
            "--out-dir", str(d / "out"), "--places", str(d / "places.jsonl"), *more,
        )  # fmt: skip

    t0 = time.monotonic()
    done = subprocess.run(replay("fast"), capture_output=True, text=True, env=env, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    times = {"fast": time.monotonic() - t0}
    busy = subprocess.Popen([*pin, "sh", "-c", "while :; do :; done"]) if pin else None
    procs: dict[str, subprocess.Popen[str]] = {}
    logs = {c: (dirs[c] / "run.log").open("w") for c in CONDITIONS[1:]}
    try:
        starts = {}
        for c, cmd in (
            ("realtime", replay("realtime", "--realtime")),
            ("pinned", [*pin, *replay("pinned", "--realtime")]),
            (
                "live",
                [*pin, *_loci(
                    "run", "--config", str(configs["live"]), "--play", str(recording),
                    "--duration", f"{seconds:g}", "--record", str(dirs["live"] / "run.mcap"),
                )],
            ),
        ):  # fmt: skip
            starts[c] = time.monotonic()
            procs[c] = subprocess.Popen(cmd, stdout=logs[c], stderr=subprocess.STDOUT, text=True, env=env)
        for c, proc in procs.items():
            rc = proc.wait(timeout=600 + 20 * seconds)
            times[c] = time.monotonic() - starts[c]
            assert rc == 0, (c, (dirs[c] / "run.log").read_text()[-3000:])
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
        if busy is not None:
            busy.kill()
            busy.wait()
        for f in logs.values():
            f.close()
    for c in CONDITIONS:
        d = dirs[c]
        if c == "live":
            poses = _places_mcap(d / "run.mcap", robot)
            nodes, edges, areas = _graph(d / "state" / "navgraph.json")
        else:
            poses = _places_jsonl(d / "places.jsonl")
            nodes, edges, areas = _graph(d / "out" / "navgraph.json")
        out[c] = Outcome(poses, nodes, edges, areas, round(times[c], 1))
    return out


def differences(outcomes: dict[str, Outcome]) -> dict[str, dict[str, Any]]:
    """Each condition against ``fast``: scans in both, the largest pose difference (metres and
    radians), labels that differ, and whether the graph's nodes, edges and the areas are equal."""
    ref = outcomes["fast"]
    out: dict[str, dict[str, Any]] = {}
    for c, o in outcomes.items():
        common = sorted(set(ref.poses) & set(o.poses))
        dxy = max(
            (math.hypot(ref.poses[k][0] - o.poses[k][0], ref.poses[k][1] - o.poses[k][1]) for k in common),
            default=math.inf,
        )
        dth = max(
            (abs(math.remainder(ref.poses[k][2] - o.poses[k][2], 2 * math.pi)) for k in common),
            default=math.inf,
        )
        out[c] = {
            "scans": len(o.poses),
            "common": len(common),
            "max_pose_m": round(dxy, 6),
            "max_heading_rad": round(dth, 6),
            "labels_differ": sum(ref.poses[k][3] != o.poses[k][3] for k in common),
            "same_nodes": o.nodes == ref.nodes,
            "same_edges": o.edges == ref.edges,
            "same_areas": o.areas == ref.areas,
            "nodes": len(o.nodes),
            "areas": len(o.areas),
            "seconds": o.seconds,
        }
    return out
