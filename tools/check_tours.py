"""Does the guided tour pass on any computer? N demo tours in each of three conditions.

``make check-tours`` (README) runs ``loci demo`` — the noisy-odometry guided tour, every
process real, on a loopback Zenoh bus — with seeds 0 … N−1 on fresh output folders, in each
condition:

* ``as-is``: the machine as it is;
* ``one-core``: every process of the tour on one core (``taskset -c 0``);
* ``one-core-busy``: on that one core beside a busy loop (``sh -c 'while :; do :; done'``,
  pinned to the same core): the processes get about half of one core.

The first tour of each condition starts with an empty numba kernel cache (``NUMBA_CACHE_DIR``
a fresh folder), as on a fresh clone; the others share that folder. For each tour it keeps
the summary's steps (passed, and each failure's step and distance), the startup time, the
localization reports and whether the robot said it was sure where it arrived. It prints the
pass rate per condition and every failure, and writes ``tours.json`` and ``tours.md``.

    python -m tools.check_tours [--tours 20] [--conditions as-is,one-core,one-core-busy]
        [--out docs/results] [--work out/tours]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

CONDITIONS = ("as-is", "one-core", "one-core-busy")


def _tour(work: Path, condition: str, seed: int, cache: Path) -> dict[str, Any]:
    out = work / condition / f"seed-{seed}"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    pin = ["taskset", "-c", "0"] if condition != "as-is" else []
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONUNBUFFERED": "1"}
    busy = None
    if condition == "one-core-busy":
        busy = subprocess.Popen(["taskset", "-c", "0", "sh", "-c", "while :; do :; done"])
    t0 = time.monotonic()
    try:
        proc = subprocess.run(
            [*pin, sys.executable, "-m", "agent.cli", "demo", "--out-dir", str(out), "--seed", str(seed)],
            capture_output=True,
            text=True,
            env=env,
            timeout=900,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return {"seed": seed, "passed": False, "failures": [{"step": "timeout", "failure": "over 900 s"}]}
    finally:
        if busy is not None:
            busy.kill()
            busy.wait()
    wall = time.monotonic() - t0
    (out / "demo.out").write_text(proc.stdout + proc.stderr, encoding="utf-8")
    path = out / "summary.json"
    if not path.is_file():
        tail = (proc.stdout + proc.stderr)[-400:]
        return {
            "seed": seed,
            "passed": False,
            "wall_s": round(wall, 1),
            "failures": [{"step": "no summary", "failure": tail}],
        }
    s = json.loads(path.read_text(encoding="utf-8"))
    failures = [
        {"step": st["step"], "failure": st["failure"], "metres": st["evidence"].get("metres_from_node")}
        for st in s["steps"]
        if not st["passed"]
    ]
    if not s.get("replay", {}).get("passed", False):
        failures.append({"step": "replay", "failure": str(s.get("replay", {}).get("failure", "no replay"))})
    drives = {
        st["step"]: {
            "metres": st["evidence"].get("metres_from_node"),
            "certain": st["evidence"].get("certain"),
        }
        for st in s["steps"]
        if st["step"] in ("go_tv", "go_station")
    }
    return {
        "seed": seed,
        "passed": bool(s.get("passed")),
        "wall_s": round(wall, 1),
        "startup_s": s.get("timings_s", {}).get("startup"),
        "failures": failures,
        "drives": drives,
        "localization": s.get("localization", []),
    }


def run(tours: int, conditions: list[str], work: Path) -> dict[str, list[dict[str, Any]]]:
    report: dict[str, list[dict[str, Any]]] = {}
    for condition in conditions:
        cache = Path(tempfile.mkdtemp(prefix=f"loci-numba-{condition}-"))  # empty: the first tour starts cold
        rows = []
        try:
            for seed in range(tours):
                row = _tour(work, condition, seed, cache)
                rows.append(row)
                mark = "ok  " if row["passed"] else "FAIL"
                why = "; ".join(f"{f['step']}: {f['failure']}" for f in row["failures"])
                print(
                    f"{condition:14s} seed {seed:2d} {mark} start {row.get('startup_s')} s, "
                    f"tour+replay {row.get('wall_s')} s{('  ' + why) if why else ''}",
                    flush=True,
                )
        finally:
            shutil.rmtree(cache, ignore_errors=True)
        report[condition] = rows
    return report


def markdown(report: dict[str, list[dict[str, Any]]], command: str) -> str:
    lines = [
        "# The guided tour on any computer",
        "",
        f"Made by `{command}` ({time.strftime('%Y-%m-%d')}, this machine: {os.cpu_count()} cores).",
        "Each condition: seeds 0 … N−1 of `loci demo` (noisy odometry, pose tracking), fresh output",
        "folders, the first tour with an empty numba kernel cache.",
        "",
        "| condition | tours | passed every step | failures | startup s (first, median) |",
        "| --- | ---: | ---: | --- | --- |",
    ]
    for condition, rows in report.items():
        passed = sum(r["passed"] for r in rows)
        fails = "; ".join(
            f"seed {r['seed']}: " + ", ".join(f"{f['step']} ({f['failure']})" for f in r["failures"])
            for r in rows
            if not r["passed"]
        )
        starts = [r["startup_s"] for r in rows if r.get("startup_s") is not None]
        first = starts[0] if starts else "—"
        med = sorted(starts)[len(starts) // 2] if starts else "—"
        lines.append(f"| {condition} | {len(rows)} | {passed} | {fails or '—'} | {first}, {med} |")
    lines.append("")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.check_tours", description=__doc__.split("\n\n")[0])
    ap.add_argument("--tours", type=int, default=20, help="tours per condition (seeds 0 … N-1; default 20)")
    ap.add_argument(
        "--conditions",
        default=",".join(CONDITIONS),
        help=f"comma-separated, of {', '.join(CONDITIONS)} (default all)",
    )
    ap.add_argument("--work", type=Path, default=Path("out/tours"), help="the tours' output folders")
    ap.add_argument("--out", type=Path, default=None, help="write tours.json and tours.md here")
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    conditions = [c for c in args.conditions.split(",") if c]
    bad = [c for c in conditions if c not in CONDITIONS]
    if bad:
        ap.error(f"unknown condition {bad[0]!r}: choose from {', '.join(CONDITIONS)}")
    if any(c != "as-is" for c in conditions) and shutil.which("taskset") is None:
        ap.error("taskset (util-linux) is needed for the one-core conditions")
    report = run(args.tours, conditions, args.work)
    print()
    for condition, rows in report.items():
        print(f"{condition:14s} {sum(r['passed'] for r in rows)} of {len(rows)} tours passed every step")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "tours.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
        command = "python -m tools.check_tours " + " ".join(argv if argv is not None else sys.argv[1:])
        (args.out / "tours.md").write_text(markdown(report, command.strip()), encoding="utf-8")
    return 0 if all(r["passed"] for rows in report.values() for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
