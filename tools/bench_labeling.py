"""Benchmark: whole-map place labeling of lab_intel (every free cell, 360 beams each).

The issue's target: ≤ 10 s on one core for lab_intel (≈309 k free cells at 0.05 m); the
C++ reference implementation of the same method (ipa_room_segmentation's "semantic"
labeler) takes 54 s for this map on this machine with one thread.

The baseline measured in the same process is the same pipeline built from the slow
reference parts (the cell-by-cell ray caster and the plain-Python feature definitions)
on a sample of cells, extrapolated per cell: it is what the method costs without the
engineering. numba is limited to one thread for the run.

Run: ``python -m tools.bench_labeling [--model M] [--json | --json-file FILE]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import data_dir
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import reference_cast
from knowledge.places.features.reference import reference_features
from knowledge.places.labeling import label_map
from knowledge.places.model import PlaceModel, default_map_model_path

#: The C++ reference's time for lab_intel on this machine, one thread (from the issue).
CPP_REFERENCE_SECONDS = 54.0


def run(data: Path | None = None, model_path: Path | None = None, *, sample: int = 40) -> dict[str, Any]:
    data = data or data_dir()
    path = data / "ipa" / "labeled" / "lab_intel.map.png"
    if not path.is_file():
        raise SystemExit(f"{path} not found: pass --data or set LOCI_DATA")
    grid = OccupancyGrid.from_image(path, 0.05)
    model = PlaceModel.load(model_path or default_map_model_path())
    n_free = int(grid.free.sum())
    # warm up: compile (or load from the cache) every kernel on a small slice
    label_map(grid, model, cells=grid.free_cells()[:64])

    tracemalloc.start()
    t0 = time.perf_counter()
    c0 = time.process_time()
    result = label_map(grid, model)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()

    # the baseline: the reference caster and features on a sample of cells
    rng = np.random.default_rng(0)
    cells = grid.free_cells()[rng.choice(n_free, size=sample, replace=False)]
    poses = np.column_stack([grid.cell_to_world(cells), np.zeros(sample)])
    t1 = time.perf_counter()
    ranges = reference_cast(grid, poses, n_beams=model.scan.n_beams, max_range=model.scan.max_range)
    t2 = time.perf_counter()
    names = [model.feature_names[i] for i in model.prediction_columns()]
    X = np.array([reference_features(r, names, max_range=model.scan.max_range) for r in ranges])
    t3 = time.perf_counter()
    ref_per_cell = (t3 - t1) / sample
    ref_cast = (t2 - t1) / sample
    ref_feat = (t3 - t2) / sample
    del X
    return {
        "map": "lab_intel",
        "free_cells": n_free,
        "beams": model.scan.n_beams,
        "model": str(model_path or "bundled default"),
        "features_for_prediction": len(names),
        "seconds": round(wall, 3),
        "cpu_seconds": round(cpu, 3),
        "stages_s": {k: round(v, 3) for k, v in result.timings.items()},
        "per_cell_us": round(1e6 * wall / n_free, 2),
        "peak_traced_mb": round(peak / 2**20, 1),
        "reference_pipeline_per_cell_ms": round(1e3 * ref_per_cell, 2),
        "reference_cast_per_cell_ms": round(1e3 * ref_cast, 2),
        "reference_features_per_cell_ms": round(1e3 * ref_feat, 2),
        "speedup_vs_reference_pipeline": round(ref_per_cell * n_free / wall, 1),
        "target_seconds": 10.0,
        "cpp_reference_seconds": CPP_REFERENCE_SECONDS,
        "speedup_vs_cpp_reference": round(CPP_REFERENCE_SECONDS / wall, 2),
    }


def report(r: dict[str, Any]) -> str:
    """The result as text."""
    return "\n".join(
        [
            f"whole-map labeling of lab_intel: {r['free_cells']:,} cells × {r['beams']} beams",
            f"  {r['seconds']:.2f} s wall ({r['cpu_seconds']:.2f} s CPU, one thread): cast {r['stages_s']['cast']:.2f} s, "
            f"features + classify {r['stages_s']['classify']:.2f} s; {r['per_cell_us']:.1f} µs per cell",
            f"  target ≤ {r['target_seconds']:.0f} s; the C++ reference takes {CPP_REFERENCE_SECONDS:.0f} s "
            f"({r['speedup_vs_cpp_reference']:.1f}× faster)",
            f"  reference parts in this process: {r['reference_pipeline_per_cell_ms']:.1f} ms per cell "
            f"→ {r['speedup_vs_reference_pipeline']:.0f}× slower than the pipeline",
            f"  peak traced memory {r['peak_traced_mb']:.0f} MB",
        ]
    )


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_labeling", description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--model", type=Path, default=None, help="place model (default: the bundled one)")
    ap.add_argument("--sample", type=int, default=40, help="cells for the reference baseline")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run(args.data, args.model, sample=args.sample)
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
