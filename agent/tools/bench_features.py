"""Benchmark: scan feature extraction (book App. A, B) against the slow reference.

Feature vectors per second on realistic random 360° scans (rooms with doors and furniture,
corridors, door frames; :mod:`knowledge.places.features.synthetic`) for

* all default features (309), and
* a typical model's subset: 150 names drawn at random with a fixed seed,

and the same on a few scans with the plain-Python reference definitions
(:mod:`knowledge.places.features.reference`) in the same process, as a ratio. A breakdown
per kernel group shows where the time goes. Timings are the best of ``repeats`` runs; the
machine's load average is reported because other processes skew them.

    python -m agent.tools.bench_features [--scans 20000] [--subset 150] [--reference 4]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from knowledge.fileio import atomic_write_text
from knowledge.places.features import FeatureExtractor, default_feature_names
from knowledge.places.features.reference import reference_features
from knowledge.places.features.registry import FAMILIES, parse_name
from knowledge.places.features.synthetic import random_scans

MAX_RANGE = 30.0


def _best_time(fx: FeatureExtractor, ranges: np.ndarray, repeats: int) -> float:
    best = float("inf")
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fx(ranges)
        best = min(best, time.perf_counter() - t0)
    return best


def _reference_time(ranges: np.ndarray, names: list[str]) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    values = np.stack([reference_features(r, names, max_range=MAX_RANGE) for r in ranges])
    return (time.perf_counter() - t0) / len(ranges), values


def run(
    n_scans: int = 20_000,
    *,
    subset_size: int = 150,
    reference_scans: int = 4,
    repeats: int = 2,
    seed: int = 0,
    num_beams: int = 360,
    breakdown: bool = True,
) -> dict[str, Any]:
    """Time the extractor on ``n_scans`` synthetic scans and the reference on a few.

    Returns scans per second (all features, the subset), per-scan times in microseconds,
    the speed-ups over the reference, the largest relative deviation from the reference on
    its sample, and (``breakdown``) microseconds per scan for each kernel group.
    """
    rng = np.random.default_rng(seed)
    ranges, _ = random_scans(n_scans, rng=rng, num_beams=num_beams, max_range=MAX_RANGE)
    names = default_feature_names()
    subset = [
        names[j]
        for j in sorted(np.random.default_rng(seed + 1).choice(len(names), subset_size, replace=False))
    ]
    result: dict[str, Any] = {
        "n_scans": n_scans,
        "num_beams": num_beams,
        "n_features": len(names),
        "subset_size": subset_size,
        "subset_fourier": sum(parse_name(n).family == "B.6" for n in subset),
        "load_average_1min": os.getloadavg()[0],
    }
    for key, ns in (("all", names), ("subset", subset)):
        fx = FeatureExtractor(ns, max_range=MAX_RANGE)
        fx(ranges[:64])  # warm caches and plans
        seconds = _best_time(fx, ranges, repeats)
        result[f"{key}_scans_per_s"] = n_scans / seconds
        result[f"{key}_us_per_scan"] = 1e6 * seconds / n_scans

    sample = ranges[:reference_scans]
    for key, ns in (("all", names), ("subset", subset)):
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
    return result


def format_result(r: dict[str, Any]) -> str:
    lines = [
        f"feature benchmark: {r['n_scans']} scans x {r['num_beams']} beams "
        f"(load average {r['load_average_1min']:.1f})",
        f"  all {r['n_features']} features: {r['all_scans_per_s']:9.0f} scans/s "
        f"({r['all_us_per_scan']:.0f} us/scan), {r['all_speedup']:.0f}x the reference "
        f"({r['all_reference_us_per_scan'] / 1e3:.0f} ms/scan), max rel. deviation {r['all_max_rel_deviation']:.1e}",
        f"  subset of {r['subset_size']} ({r['subset_fourier']} Fourier): {r['subset_scans_per_s']:9.0f} scans/s "
        f"({r['subset_us_per_scan']:.0f} us/scan), {r['subset_speedup']:.0f}x the reference "
        f"({r['subset_reference_us_per_scan'] / 1e3:.0f} ms/scan), max rel. deviation {r['subset_max_rel_deviation']:.1e}",
    ]
    if "group_us_per_scan" in r:
        lines.append("  per kernel group (all its default features), us/scan:")
        for g, us in sorted(r["group_us_per_scan"].items(), key=lambda kv: -kv[1]):
            lines.append(f"    {g:8s} {r['group_sizes'][g]:4d} features {us:8.1f}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m agent.tools.bench_features", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--scans", type=int, default=20_000, help="synthetic 360° scans to featurise")
    parser.add_argument("--subset", type=int, default=150, help="size of the random 'typical model' subset")
    parser.add_argument("--reference", type=int, default=4, help="scans for the slow reference")
    parser.add_argument("--repeats", type=int, default=2, help="timed runs; the best counts")
    parser.add_argument("--no-breakdown", action="store_true", help="skip the per-group timing")
    parser.add_argument("--json", type=Path, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    r = run(
        args.scans,
        subset_size=args.subset,
        reference_scans=args.reference,
        repeats=args.repeats,
        breakdown=not args.no_breakdown,
    )
    print(format_result(r))
    if args.json:
        atomic_write_text(args.json, json.dumps(r, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
