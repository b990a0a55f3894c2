"""``make bench``: run every benchmark in its own process and collect the results.

Each benchmark measures speed as a ratio against a baseline run in the same process (the
slow reference implementation, scikit-learn, the line rate, ...). This driver runs them
one after the other (never in parallel: they would disturb each other), each once with
``--json-file bench/NAME.json`` (its numbers) while its text report is kept in
``bench/NAME.md``, and writes ``bench.md`` with the commands and the reports.

Run: ``make bench`` or ``python -m tools.bench --out docs/results``.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from knowledge.fileio import atomic_write_text

#: (name, module, extra arguments, what it measures)
BENCHMARKS: list[tuple[str, str, list[str], str]] = [
    ("raycast", "tools.bench_raycast", [], "ray casting: rays per second vs the reference caster"),
    ("features", "tools.bench_features", [], "scan features: vectors per second vs the reference"),
    (
        "labeling",
        "tools.bench_labeling",
        [],
        "whole-map labeling of lab_intel (target ≤ 10 s, one core)",
    ),
    ("boosting", "tools.bench_boosting", [], "AdaBoost training vs scikit-learn (target ≥ 5×)"),
    ("topology", "tools.bench_topology", [], "relaxation and regions on office_g"),
    ("sick", "tools.bench_sick", [], "SICK telegram codec vs the 500 kbaud line rate"),
    ("people", "tools.bench_people", [], "leg detection per 768-beam scan vs 75 Hz"),
    (
        "conceptual",
        "tools.bench_conceptual",
        [],
        "the conceptual map: a new object to the inferred room type (target ≤ 2 s), answers from the cache (≤ 100 ms)",
    ),
    ("objects", "tools.bench_objects", [], "object recognition: rendered views of the tour's objects"),
    (
        "agent",
        "tools.bench_agent",
        [],
        "the agent per scan: latency telegram → place (target p99 < 5 ms), sustained rate, memory over an hour",
    ),
    (
        "live",
        "tools.bench_live",
        [],
        "the Foxglove live view's cost per scan: off, served with no client, watched by one client (target p99 < 5 ms)",
    ),
    (
        "localization",
        "tools.bench_localization",
        [],
        "the particle filter: updates per second against particles, 180 beams, one core (target 10,000 at ≥ 10 Hz)",
    ),
    (
        "tracking",
        "tools.bench_tracking",
        [],
        "pose tracking in the agent: the per-scan path with the tracker off, inline and on its own thread (target p99 < 5 ms)",
    ),
    (
        "startup",
        "tools.bench_startup",
        [],
        "a restarted agent's time to answer against its saved map (500-5,000 nodes), vs an empty map",
    ),
    (
        "replay",
        "tools.bench_replay",
        [],
        "replaying the real Freiburg 079 log: scans/s against the log's own pace, per-scan time on real scans",
    ),
]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("docs/results"), help="where bench.md and the JSON go")
    ap.add_argument("--only", action="append", default=[], help="run only these (repeatable)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    outdir = args.out / "bench"
    outdir.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    failed: list[str] = []
    for name, module, extra, what in BENCHMARKS:
        if args.only and name not in args.only:
            continue
        json_path = outdir / f"{name}.json"
        # each benchmark prints its text report and writes the same numbers with --json-file
        cmd = [sys.executable, "-m", module, *extra, "--json-file", str(json_path)]
        print(f"[bench] {name}: {what} ...", file=sys.stderr, flush=True)
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        seconds = time.perf_counter() - t0
        if proc.returncode != 0:
            failed.append(name)
            report = f"FAILED (exit {proc.returncode})\n{proc.stderr[-2000:]}"
        else:
            report = proc.stdout.rstrip()
        shown = " ".join(["python -m", module, *extra])
        when = datetime.now(UTC).date().isoformat()
        section = [
            f"## {name}: {what}",
            "",
            f"`{shown}` ({seconds:.0f} s, {when}, load {load:.1f} at start)",
            "",
            "```",
            report,
            "```",
            "",
        ]
        atomic_write_text(outdir / f"{name}.md", "\n".join(section))
    # bench.md collects every benchmark's latest section, so `--only X` refreshes X alone
    sections: list[str] = []
    for name, *_ in BENCHMARKS:
        part = outdir / f"{name}.md"
        sections += [part.read_text(encoding="utf-8")] if part.exists() else [f"## {name}: not run yet", ""]
    # sections made by hand or by a one-off run (each says its command), kept when bench.md is remade
    sections += [part.read_text(encoding="utf-8") for part in sorted((outdir / "extra").glob("*.md"))]
    head = [
        "# Benchmarks",
        "",
        "Made by `make bench` (`python -m tools.bench`), one benchmark per process, one after "
        "the other, numba and BLAS limited to one thread.",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
        "each section says when it ran. Speeds are ratios against baselines run in the same "
        "process; absolute times depend on the machine and on what else runs on it.",
        "",
    ]
    atomic_write_text(args.out / "bench.md", "\n".join(head + sections))
    print("\n".join(head + sections))
    if failed:
        print(f"[bench] failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
