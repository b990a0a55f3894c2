"""Benchmark: the particle filter's update rate against the number of particles, on one core.

On the raw Freiburg 079 map (``ipa/raw/freiburg_building79.png``, 0.05 m) a 180° laser with
``--beams`` beams (default 180, all used) is simulated along a straight drive; each
:meth:`~knowledge.localization.mcl.ParticleFilter.update` moves every particle (the
odometry motion model), weighs it by the likelihood field over every beam and by the map,
and resamples when the effective sample size asks (``update_distance`` 0: every call is a
measurement update). Timed per particle count after a warm-up; the baseline, in the same
process, is the same weighting written in plain numpy (a vectorised reference), so the
ratio says what the compiled kernel buys. Target: 10,000 particles at ≥ 10 Hz.

    python -m agent.tools.bench_localization [--beams 180] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from knowledge.fileio import atomic_write_text
from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.mcl import MclParams, ParticleFilter, beam_log_likelihood
from knowledge.metric import OccupancyGrid
from knowledge.metric.beams import beam_angles
from knowledge.metric.raycast import cast

DEFAULT_DATA = Path(os.environ.get("LOCI_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
MAP = Path("ipa") / "raw" / "freiburg_building79.png"
COUNTS = (1_000, 2_000, 5_000, 10_000, 20_000, 50_000)


def numpy_log_likelihood(
    particles: np.ndarray, bx: np.ndarray, by: np.ndarray, logp: np.ndarray, res: float, outside: float
) -> np.ndarray:
    """The reference: :func:`~knowledge.localization.mcl.beam_log_likelihood` in numpy."""
    c, s = np.cos(particles[:, 2:3]), np.sin(particles[:, 2:3])
    ex = particles[:, 0:1] + c * bx - s * by
    ey = particles[:, 1:2] + s * bx + c * by
    col = np.floor(ex / res).astype(np.int64)
    row = np.floor(ey / res).astype(np.int64)
    inside = (row >= 0) & (row < logp.shape[0]) & (col >= 0) & (col < logp.shape[1])
    vals = np.full(ex.shape, outside)
    vals[inside] = logp[row[inside], col[inside]]
    return vals.sum(axis=1)


def run(data: Path, beams: int = 180, repeats: int = 20) -> dict[str, Any]:
    path = data / MAP
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the benchmark needs the ipa raw maps of ../shared/data")
    grid = OccupancyGrid.from_image(path, 0.05)
    field = LikelihoodField.from_grid(grid)
    free = field.free_positions()
    rng = np.random.default_rng(0)
    start = free[rng.integers(0, len(free))]
    poses = np.array([[start[0] + 0.05 * k, start[1], 0.0] for k in range(repeats + 5)])
    world = field.to_world(poses)
    angles = beam_angles(beams, math.pi)
    scans = cast(grid, world, n_beams=beams, fov=math.pi, max_range=20.0, unknown_blocks=False)
    prm = MclParams(beams=beams, update_distance=0.0, update_angle=0.0, alpha_fast=0.0)
    out: dict[str, Any] = {"map": str(MAP), "cells": list(grid.shape), "beams": beams, "rows": []}
    for n in COUNTS:
        pf = ParticleFilter(field, replace(prm, particles=n), rng=np.random.default_rng(1))
        pf.init_uniform()
        for k in range(3):  # warm-up (compiles on the first call)
            pf.update(world[k], scans[k], angles, range_max=20.0)
        t0 = time.perf_counter()
        for k in range(3, 3 + repeats):
            pf.update(world[k], scans[k], angles, range_max=20.0)
        per = (time.perf_counter() - t0) / repeats
        # the weighting alone, compiled and in numpy, on the same particles and beams
        bx, by = pf._endpoints(scans[0], angles, 20.0, 0.0)
        P = np.ascontiguousarray(pf.particles)
        t0 = time.perf_counter()
        for _ in range(3):
            fast = beam_log_likelihood(P, bx, by, pf._logp, field.resolution, pf._outside)
        t_fast = (time.perf_counter() - t0) / 3
        t0 = time.perf_counter()
        ref = numpy_log_likelihood(P, bx, by, pf._logp, field.resolution, pf._outside)
        t_ref = time.perf_counter() - t0
        row = {
            "particles": n,
            "update_ms": round(1e3 * per, 2),
            "hz": round(1.0 / per, 1),
            "weighting_ms": round(1e3 * t_fast, 2),
            "numpy_weighting_ms": round(1e3 * t_ref, 2),
            "speedup_vs_numpy": round(t_ref / t_fast, 1),
            "max_abs_difference": float(np.max(np.abs(fast - ref))),
        }
        out["rows"].append(row)
        print(row, file=sys.stderr, flush=True)
    ten = next(r for r in out["rows"] if r["particles"] == 10_000)
    out["target"] = {"particles": 10_000, "hz": ten["hz"], "met": ten["hz"] >= 10.0}
    return out


def report(res: dict[str, Any]) -> str:
    lines = [
        f"Particle filter update on {res['map']} ({res['cells'][0]}x{res['cells'][1]} cells), "
        f"{res['beams']} beams, one core:",
        "",
        "| particles | update ms | Hz | weighting ms | numpy weighting ms | speed-up |",
        "| ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in res["rows"]:
        lines.append(
            f"| {r['particles']:,} | {r['update_ms']} | {r['hz']} | {r['weighting_ms']} | "
            f"{r['numpy_weighting_ms']} | {r['speedup_vs_numpy']}× |"
        )
    t = res["target"]
    lines += ["", f"Target 10,000 particles at ≥ 10 Hz: {t['hz']} Hz ({'met' if t['met'] else 'missed'})."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m agent.tools.bench_localization", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--beams", type=int, default=180)
    ap.add_argument("--json", type=Path, help="write the numbers here")
    args = ap.parse_args(argv)
    res = run(args.data, args.beams)
    print(report(res))
    if args.json:
        atomic_write_text(args.json, json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
