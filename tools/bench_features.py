"""Benchmark: scan feature extraction (book App. A, B) against the slow reference.

Microseconds per scan on realistic random 360° scans (rooms with doors and furniture,
corridors, door frames; :mod:`knowledge.places.features.synthetic`) for

* all default features (309; training computes them all),
* the prediction features of a real trained model (:data:`TYPICAL_MODEL_FEATURES`, 80 names;
  whole-map labeling computes these for every free cell), and
* a random subset of 150 names (fixed seed),

with the projected time for a whole map (:data:`WHOLE_MAP_SCANS` scans, lab_intel), the speed-up
over the plain-Python reference definitions (:mod:`knowledge.places.features.reference`,
timed on a few scans in the same process) and the largest relative deviation from it. A
breakdown per kernel group shows where the time goes, and the numba compile time of the
kernels on a cold cache (a fresh process with an empty cache directory) is reported apart.

Single-threaded. Timings are per slice of scans the fastest of ``repeats`` runs, summed over
the slices: on a shared machine short runs that nobody interrupted are the best estimate of
the code's own cost. The machine's load average is reported because other processes skew them.

    python -m tools.bench_features [--scans 20000] [--reference 4] [--no-compile]
                                   [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import REPO
from knowledge.places.features import FeatureExtractor, default_feature_names
from knowledge.places.features.reference import reference_features
from knowledge.places.features.registry import FAMILIES, parse_name
from knowledge.places.features.synthetic import random_scans

MAX_RANGE = 30.0
#: Free cells (one scan each) of the lab_intel map: the whole-map labeling workload.
WHOLE_MAP_SCANS = 309_000
#: Scans per timed slice.
_SLICE = 250
#: The prediction features of a trained place model (boosting picked these 80 of the 309).
TYPICAL_MODEL_FEATURES = (
    "A.1",
    "A.3[maxrange=1m]",
    "A.3[maxrange=1.5m]",
    "A.3[maxrange=2m]",
    "A.3[maxrange=2.5m]",
    "A.3[maxrange=3.5m]",
    "A.3[maxrange=4m]",
    "A.3[maxrange=5m]",
    "A.3[maxrange=8m]",
    "A.4[maxrange=1m]",
    "A.4[maxrange=1.5m]",
    "A.4[maxrange=10m]",
    "A.4[maxrange=15m]",
    "A.4[maxrange=25m]",
    "A.5",
    "A.6",
    "A.7[gap=0.05m]",
    "A.7[gap=0.1m]",
    "A.7[gap=0.15m]",
    "A.7[gap=0.3m]",
    "A.7[gap=2m]",
    "A.7[gap=3m]",
    "A.8[w=5,eps=0.01m]",
    "A.8[w=10,eps=0.01m]",
    "A.8[w=10,eps=0.02m]",
    "A.8[w=10,eps=0.05m]",
    "A.8[w=10,eps=0.1m]",
    "A.8[w=20,eps=0.01m]",
    "A.8[w=20,eps=0.02m]",
    "A.8[w=20,eps=0.05m]",
    "A.9",
    "A.10",
    "A.11",
    "A.12",
    "A.13",
    "A.14",
    "A.15[ratio=1.05]",
    "A.15[ratio=1.4]",
    "A.15[ratio=1.5]",
    "A.15[ratio=3]",
    "A.15[ratio=5]",
    "A.16",
    "B.1",
    "B.3",
    "B.4",
    "B.5",
    "B.6[n=-1]",
    "B.6[n=2]",
    "B.6[n=-2]",
    "B.6[n=3]",
    "B.6[n=-3]",
    "B.6[n=4]",
    "B.6[n=-4]",
    "B.6[n=5]",
    "B.6[n=-5]",
    "B.6[n=6]",
    "B.6[n=-6]",
    "B.6[n=11]",
    "B.6[n=-15]",
    "B.6[n=-16]",
    "B.6[n=-17]",
    "B.6[n=50]",
    "B.6[n=85]",
    "B.6[n=-89]",
    "B.6[n=-94]",
    "B.6[n=-95]",
    "B.7",
    "B.8",
    "B.9[phi=2]",
    "B.9[phi=3]",
    "B.9[phi=4]",
    "B.9[phi=5]",
    "B.9[phi=6]",
    "B.9[phi=7]",
    "B.10",
    "B.11",
    "B.12",
    "B.13",
    "B.15",
    "B.16",
)


def _best_time(fx: FeatureExtractor, ranges: np.ndarray, repeats: int) -> float:
    """Seconds for ``ranges``: per slice of :data:`_SLICE` scans the fastest of ``repeats`` runs, summed."""
    total = 0.0
    for start in range(0, len(ranges), _SLICE):
        part = ranges[start : start + _SLICE]
        best = float("inf")
        for _ in range(max(1, repeats)):
            t0 = time.perf_counter()
            fx(part)
            best = min(best, time.perf_counter() - t0)
        total += best
    return total


def _reference_time(ranges: np.ndarray, names: Sequence[str]) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    values = np.stack([reference_features(r, names, max_range=MAX_RANGE) for r in ranges])
    return (time.perf_counter() - t0) / len(ranges), values


_COLD_SCRIPT = """
import time
t0 = time.perf_counter()
import numpy as np
from knowledge.places.features import FeatureExtractor, default_feature_names
t1 = time.perf_counter()
FeatureExtractor(default_feature_names(), max_range=30.0)(np.full((2, 360), 3.0))
print(t1 - t0, time.perf_counter() - t1)
"""


def compile_seconds() -> dict[str, float]:
    """Import and first-call seconds of a fresh process, with an empty numba cache (cold:
    the kernels are compiled) and again with the cache it filled (warm: they are loaded)."""
    result: dict[str, float] = {}
    root = REPO
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for key in ("cold", "warm"):
            out = subprocess.run(
                [sys.executable, "-c", _COLD_SCRIPT],
                cwd=root,
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            imported, first_call = (float(v) for v in out.stdout.split())
            result[f"{key}_import_s"] = imported
            result[f"{key}_first_call_s"] = first_call
    return result


def run(
    n_scans: int = 20_000,
    *,
    subset_size: int = 150,
    reference_scans: int = 4,
    repeats: int = 5,
    seed: int = 0,
    num_beams: int = 360,
    breakdown: bool = True,
    compile_time: bool = True,
) -> dict[str, Any]:
    """Time the extractor on ``n_scans`` synthetic scans and the reference on a few.

    Returns, for each feature set (``all``, ``typical``, ``subset``), microseconds per scan,
    the projected seconds for :data:`WHOLE_MAP_SCANS` scans, the speed-up over the reference
    and the largest relative deviation from it on its sample; (``breakdown``) microseconds
    per scan for each kernel group; (``compile_time``) :func:`compile_seconds`.
    """
    rng = np.random.default_rng(seed)
    ranges, _ = random_scans(n_scans, rng=rng, num_beams=num_beams, max_range=MAX_RANGE)
    names = default_feature_names()
    subset = [
        names[j]
        for j in sorted(np.random.default_rng(seed + 1).choice(len(names), subset_size, replace=False))
    ]
    sets = {"all": names, "typical": list(TYPICAL_MODEL_FEATURES), "subset": subset}
    result: dict[str, Any] = {
        "n_scans": n_scans,
        "num_beams": num_beams,
        "whole_map_scans": WHOLE_MAP_SCANS,
        "load_average_1min": os.getloadavg()[0],
        "sizes": {key: len(ns) for key, ns in sets.items()},
        "fourier_counts": {key: sum(parse_name(n).family == "B.6" for n in ns) for key, ns in sets.items()},
    }
    for key, ns in sets.items():
        fx = FeatureExtractor(ns, max_range=MAX_RANGE)
        fx(ranges[:64])  # compile or load the kernels
        seconds = _best_time(fx, ranges, repeats)
        result[f"{key}_us_per_scan"] = 1e6 * seconds / n_scans
        result[f"{key}_whole_map_s"] = seconds / n_scans * WHOLE_MAP_SCANS

    sample = ranges[:reference_scans]
    for key, ns in sets.items():
        ref_s, ref = _reference_time(sample, ns)
        fast = FeatureExtractor(ns, max_range=MAX_RANGE, dtype=np.float64)(sample)
        scale = np.maximum(np.abs(ref), 1e-9)
        result[f"{key}_reference_us_per_scan"] = 1e6 * ref_s
        result[f"{key}_speedup"] = ref_s / (result[f"{key}_us_per_scan"] * 1e-6)
        result[f"{key}_max_rel_deviation"] = float(np.max(np.abs(fast - ref) / scale))

    if breakdown:
        groups: dict[str, list[str]] = {}
        for n in names:
            groups.setdefault(FAMILIES[parse_name(n).family].group, []).append(n)
        part = ranges[: min(n_scans, 4000)]
        result["group_us_per_scan"] = {
            g: 1e6 * _best_time(FeatureExtractor(ns, max_range=MAX_RANGE), part, repeats) / len(part)
            for g, ns in groups.items()
        }
        result["group_sizes"] = {g: len(ns) for g, ns in groups.items()}
    if compile_time:
        result["compile"] = compile_seconds()
    return result


def format_result(r: dict[str, Any]) -> str:
    lines = [
        f"feature benchmark: {r['n_scans']} scans x {r['num_beams']} beams, one thread "
        f"(load average {r['load_average_1min']:.1f})",
    ]
    labels = {"all": "all features", "typical": "typical model", "subset": "random subset"}
    for key, label in labels.items():
        lines.append(
            f"  {label:14s} {r['sizes'][key]:4d} ({r['fourier_counts'][key]:3d} B.6): "
            f"{r[f'{key}_us_per_scan']:7.1f} us/scan, {r[f'{key}_whole_map_s']:6.1f} s for "
            f"{r['whole_map_scans']} scans; {r[f'{key}_speedup']:6.0f}x the reference "
            f"({r[f'{key}_reference_us_per_scan'] / 1e3:.0f} ms/scan), "
            f"max rel. deviation {r[f'{key}_max_rel_deviation']:.1e}"
        )
    if "group_us_per_scan" in r:
        lines.append("  per kernel group (all its default features), us/scan:")
        for g, us in sorted(r["group_us_per_scan"].items(), key=lambda kv: -kv[1]):
            lines.append(f"    {g:8s} {r['group_sizes'][g]:4d} features {us:8.1f}")
    if "compile" in r:
        c = r["compile"]
        lines.append(
            f"  numba kernels: cold cache {c['cold_first_call_s']:.1f} s to compile "
            f"(import {c['cold_import_s']:.1f} s), warm cache {c['warm_first_call_s']:.2f} s to load "
            f"(import {c['warm_import_s']:.1f} s)"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tools.bench_features", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--scans", type=int, default=20_000, help="synthetic 360° scans to featurise")
    parser.add_argument("--subset", type=int, default=150, help="size of the random subset")
    parser.add_argument("--reference", type=int, default=4, help="scans for the slow reference")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per slice; the fastest counts")
    parser.add_argument("--no-breakdown", action="store_true", help="skip the per-group timing")
    parser.add_argument("--no-compile", action="store_true", help="skip the cold-cache compile timing")
    add_json_option(parser)
    add_json_file_option(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run(
        args.scans,
        subset_size=args.subset,
        reference_scans=args.reference,
        repeats=args.repeats,
        breakdown=not args.no_breakdown,
        compile_time=not args.no_compile,
    )
    emit_result(args, r, format_result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
