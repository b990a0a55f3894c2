"""Benchmark: ray casting speed on a real map, as ratios against the reference caster.

Measures, in one process and on one core:

- ``cast_cells`` on every free cell of ``lab_intel`` at 0.05 m (≈309 k cells × 360 beams):
  whole-map seconds (fresh output, and into a reused buffer), rays per second and peak
  extra memory (growth of the peak resident set);
- ``cast`` on random poses (batches, and one 361-beam SICK scan as the simulator asks);
- ``reference_cast`` on a small sample of the same poses, and the speed-ups against it;
- that the fast casters agree with the reference on that sample (max abs difference);
- separately, numba's compile time: a fresh process casting on a tiny map with an empty
  cache (cold: compiles everything) and again with that cache filled (warm: loads it).

The casters are warmed up (compiled or loaded) before anything is timed.

    python -m tools.bench_raycast [--data ../shared/data] [--beams 360] [--json | --json-file OUT.json]

:func:`run` returns the numbers as a dict; it needs the ipa maps under ``data_dir``
(``../shared/data`` by default) and raises FileNotFoundError naming the file otherwise.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import REPO, data_dir
from knowledge.metric import OccupancyGrid
from knowledge.metric.raycast import cast, cast_cells, reference_cast

#: ``$LOCI_DATA``, else ``../shared/data`` beside the clone (as the tests find it).
DEFAULT_DATA = data_dir()
MAP = Path("ipa") / "labeled" / "lab_intel.map.png"
RESOLUTION = 0.05


def _rss_mb() -> float:
    """Current resident set size of this process in MB (Linux)."""
    with Path("/proc/self/statm").open() as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def _peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


#: Run in a fresh process: the seconds to import the casters and to make their first calls.
_FIRST_CALLS = """
import json, time
t0 = time.perf_counter()
import numpy as np
from knowledge.metric import OccupancyGrid
from knowledge.metric.raycast import cast, cast_cells
t1 = time.perf_counter()
occ = np.zeros((6, 7), dtype=bool)
occ[0] = occ[-1] = occ[2, 3] = True
grid = OccupancyGrid.from_masks(occ, 0.1)
cast_cells(grid, n_beams=8)
cast(grid, np.array([0.33, 0.27, 0.1]), n_beams=8)
print(json.dumps({"import_s": t1 - t0, "first_calls_s": time.perf_counter() - t1}))
"""


def compile_seconds() -> dict[str, float]:
    """numba's compile time for the casters, in fresh processes sharing a new, empty cache.

    Returns ``cold_s`` (first calls compiling everything), ``warm_s`` (first calls loading
    the cache the cold run wrote) and ``import_s`` (importing the casters, numba included).
    """
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        runs = []
        for _ in range(2):
            done = subprocess.run(
                [sys.executable, "-c", _FIRST_CALLS],
                env=env,
                cwd=REPO,
                capture_output=True,
                text=True,
                check=True,
            )
            runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return {
        "cold_s": runs[0]["first_calls_s"],
        "warm_s": runs[1]["first_calls_s"],
        "import_s": runs[1]["import_s"],
    }


def _warm_up() -> None:
    """Compile (or load) the casters before anything is timed."""
    occ = np.zeros((6, 7), dtype=bool)
    occ[0] = occ[-1] = occ[2, 3] = True
    grid = OccupancyGrid.from_masks(occ, 0.1)
    cast_cells(grid, n_beams=8)
    cast(grid, np.array([0.33, 0.27, 0.1]), n_beams=8)


def _timed(fn: Any, *args: Any, **kwargs: Any) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def run(
    data_dir: Path | None = None,
    *,
    n_beams: int = 360,
    max_range: float = 30.0,
    n_poses: int = 2000,
    n_reference: int = 12,
    seed: int = 0,
    compile_time: bool = True,
) -> dict[str, Any]:
    """Time the casters on lab_intel; see the module docstring for what is measured.

    ``compile_time``: also measure numba's compile time (two fresh processes, ~10 s).
    """
    path = (data_dir or DEFAULT_DATA) / MAP
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the lab_intel map is needed (point --data at shared/data)")
    grid = OccupancyGrid.from_image(path, RESOLUTION)
    cells = grid.free_cells()
    rng = np.random.default_rng(seed)
    r: dict[str, Any] = {
        "map": str(MAP),
        "shape": list(grid.shape),
        "free_cells": len(cells),
        "n_beams": n_beams,
        "max_range_m": max_range,
    }

    if compile_time:
        r.update({f"compile_{k}": v for k, v in compile_seconds().items()})
    _warm_up()

    # whole map: every free cell, every beam; peak memory as the growth of the process's
    # peak resident set (tracemalloc would slow numpy's allocations down)
    rss0 = _rss_mb()
    cpu0 = time.process_time()
    swept, wall = _timed(cast_cells, grid, n_beams=n_beams, max_range=max_range)
    r["cells_s"] = wall
    r["cells_cpu_s"] = time.process_time() - cpu0
    r["cells_peak_extra_mb"] = _peak_rss_mb() - rss0
    r["cells_output_mb"] = swept.nbytes / 1e6
    r["cells_rays_per_s"] = swept.size / wall
    r["cells_hit_fraction"] = float((swept < max_range).mean())
    out = np.empty_like(swept)
    cast_cells(grid, n_beams=n_beams, max_range=max_range, out=out)  # touch the buffer once
    _, r["cells_reused_out_s"] = _timed(cast_cells, grid, n_beams=n_beams, max_range=max_range, out=out)

    # random poses: free cells jittered inside, random headings
    pick = rng.choice(len(cells), n_poses)
    xy = grid.cell_to_world(cells[pick]) + rng.uniform(-0.49, 0.49, (n_poses, 2)) * RESOLUTION
    poses = np.column_stack([xy, rng.uniform(-math.pi, math.pi, n_poses)])
    cast(grid, poses[:2], n_beams=n_beams, max_range=max_range)  # caches the map's blocking mask
    scans, wall = _timed(cast, grid, poses, n_beams=n_beams, max_range=max_range)
    r["cast_rays_per_s"] = scans.size / wall
    reps = 50
    t0 = time.perf_counter()
    for i in range(reps):
        cast(grid, poses[i], n_beams=361, fov=math.pi, max_range=max_range)
    r["cast_sick_scan_ms"] = (time.perf_counter() - t0) / reps * 1e3

    # the reference on a small sample, and agreement
    sample = np.arange(n_reference)
    ref, wall = _timed(reference_cast, grid, poses[sample], n_beams=n_beams, max_range=max_range)
    r["reference_rays_per_s"] = ref.size / wall
    r["cast_speedup"] = r["cast_rays_per_s"] / r["reference_rays_per_s"]
    r["cells_speedup"] = r["cells_rays_per_s"] / r["reference_rays_per_s"]
    r["cast_max_abs_diff_m"] = float(np.abs(scans[sample] - ref).max())
    centre_poses = np.column_stack([grid.cell_to_world(cells[pick[sample]]), np.zeros(n_reference)])
    ref_cells = reference_cast(grid, centre_poses, n_beams=n_beams, max_range=max_range)
    r["cells_max_abs_diff_m"] = float(np.abs(swept[pick[sample]] - ref_cells).max())
    return r


def format_result(r: dict[str, Any]) -> str:
    return "\n".join(
        [
            f"ray casting benchmark: {r['map']} {r['shape'][0]}x{r['shape'][1]} cells at {RESOLUTION} m, "
            f"{r['n_beams']} beams, max range {r['max_range_m']} m",
            f"  {'caster':<16}{'rays/s':>14}{'vs reference':>14}   notes",
            f"  {'cast_cells':<16}{r['cells_rays_per_s']:>14,.0f}{r['cells_speedup']:>13,.0f}x   "
            f"whole map ({r['free_cells']:,} cells): {r['cells_s']:.2f} s wall, {r['cells_cpu_s']:.2f} s CPU, "
            f"{r['cells_reused_out_s']:.2f} s into a reused buffer; peak extra memory "
            f"{r['cells_peak_extra_mb']:.0f} MB (of which output {r['cells_output_mb']:.0f} MB)",
            f"  {'cast':<16}{r['cast_rays_per_s']:>14,.0f}{r['cast_speedup']:>13,.0f}x   "
            f"random poses; one 361-beam SICK scan {r['cast_sick_scan_ms']:.2f} ms",
            f"  {'reference_cast':<16}{r['reference_rays_per_s']:>14,.0f}{1:>13}x",
            f"  agreement with the reference (max abs diff): cast {r['cast_max_abs_diff_m']:.2e} m, "
            f"cast_cells {r['cells_max_abs_diff_m']:.2e} m; {100 * r['cells_hit_fraction']:.1f} % of beams hit",
        ]
        + (
            [
                f"  numba compile (not in the rates above): cold cache {r['compile_cold_s']:.1f} s, "
                f"warm cache {r['compile_warm_s']:.2f} s (import {r['compile_import_s']:.2f} s)"
            ]
            if "compile_cold_s" in r
            else []
        )
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m tools.bench_raycast", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--data", type=Path, default=None, help="the shared data folder (default ../shared/data)"
    )
    parser.add_argument("--beams", type=int, default=360)
    parser.add_argument("--poses", type=int, default=2000, help="random poses for cast")
    add_json_option(parser)
    add_json_file_option(parser)
    parser.add_argument("--no-compile-time", action="store_true", help="skip measuring numba's compile time")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        r = run(args.data, n_beams=args.beams, n_poses=args.poses, compile_time=not args.no_compile_time)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    emit_result(args, r, format_result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
