"""Benchmark: the particle filter's update rate against the number of particles, on one core.

In the MIT CSAIL map (the 406 SLAM-corrected scans of ``logs/csail-corrected.log.gz`` at
their poses, 0.05 m cells, 1630 × 1192: the map the localization evaluation uses) with those
real scans (361 beams, ``--beams`` of them used, default 180) at their poses; each
:meth:`~knowledge.localization.mcl.ParticleFilter.update` moves every particle (the
odometry motion model), weighs it by the likelihood field over every beam and by the map,
and resamples when the effective sample size asks (``update_distance`` 0: every call is a
measurement update). Timed per particle count after a warm-up; the baseline, in the same
process, is the same weighting written in plain numpy (a vectorised reference), so the
ratio says what the compiled kernel buys. After the warm-up the particles have gathered
(resampled on the scans); the weighting is also timed with particles spread uniformly over
the map, as in global localization's first updates, whose lookups miss the caches.
Target: 10,000 particles at ≥ 10 Hz.

    python -m tools.bench_localization [--beams 180] [--json] [--json-file out.json]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import data_dir
from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.mcl import MclParams, ParticleFilter, beam_log_likelihood
from knowledge.metric.mapping import ScanMapper

DEFAULT_DATA = data_dir()
LOG = Path("logs") / "csail-corrected.log.gz"
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
    import tempfile

    from agent.recording.carmen import CarmenOptions
    from agent.recording.importer import import_log
    from agent.recording.reference import reference_scans

    path = data / LOG
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the benchmark needs the CSAIL log of ../shared/data")
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "csail-corrected.mcap"
        import_log(path, rec, carmen=CarmenOptions(truth="laser"), emit=lambda s: None)
        pairs = reference_scans(rec)
    mapper = ScanMapper()
    for scan, pose in pairs:
        mapper.add(scan.ranges, scan.angles, (pose.x, pose.y, pose.theta), range_max=scan.range_max)
    grid = mapper.grid("csail")
    field = LikelihoodField.from_grid(grid)
    scans = [s for s, _ in pairs[: repeats + 5]]
    world = np.array([[p.x, p.y, p.theta] for _, p in pairs[: repeats + 5]])
    angles = scans[0].angles
    rmax = float(scans[0].range_max)
    prm = MclParams(beams=beams, update_distance=0.0, update_angle=0.0, alpha_fast=0.0)
    out: dict[str, Any] = {"map": str(LOG), "cells": list(grid.shape), "beams": beams, "rows": []}
    for n in COUNTS:
        pf = ParticleFilter(field, replace(prm, particles=n), rng=np.random.default_rng(1))
        pf.init_uniform()
        for k in range(3):  # warm-up (compiles on the first call)
            pf.update(world[k], scans[k].ranges, angles, range_max=rmax)
        t0 = time.perf_counter()
        for k in range(3, 3 + repeats):
            pf.update(world[k], scans[k].ranges, angles, range_max=rmax)
        per = (time.perf_counter() - t0) / repeats
        # the weighting alone, compiled and in numpy, on the same particles and beams
        bx, by = pf._endpoints(scans[0].ranges, angles, rmax, 0.0)
        P = np.ascontiguousarray(pf.particles)
        t0 = time.perf_counter()
        for _ in range(3):
            fast = beam_log_likelihood(P, bx, by, pf._logp, field.resolution, pf._outside)
        t_fast = (time.perf_counter() - t0) / 3
        t0 = time.perf_counter()
        ref = numpy_log_likelihood(P, bx, by, pf._logp, field.resolution, pf._outside)
        t_ref = time.perf_counter() - t0
        # particles spread over the whole map (global localization's first updates): the
        # lookups then miss the caches
        U = np.ascontiguousarray(pf._uniform(n))
        t0 = time.perf_counter()
        for _ in range(3):
            beam_log_likelihood(U, bx, by, pf._logp, field.resolution, pf._outside)
        t_spread = (time.perf_counter() - t0) / 3
        row = {
            "particles": n,
            "beams_used": int(bx.size),
            "update_ms": round(1e3 * per, 2),
            "hz": round(1.0 / per, 1),
            "weighting_ms": round(1e3 * t_fast, 2),
            "weighting_spread_ms": round(1e3 * t_spread, 2),
            "hz_spread": round(1.0 / (per - t_fast + t_spread), 1),
            "numpy_weighting_ms": round(1e3 * t_ref, 2),
            "speedup_vs_numpy": round(t_ref / t_fast, 1),
            "max_abs_difference": float(np.max(np.abs(fast - ref))),
        }
        out["rows"].append(row)
        print(row, file=sys.stderr, flush=True)
    ten = next(r for r in out["rows"] if r["particles"] == 10_000)
    out["target"] = {
        "particles": 10_000,
        "hz": ten["hz"],
        "hz_spread": ten["hz_spread"],
        "met": min(ten["hz"], ten["hz_spread"]) >= 10.0,
    }
    return out


def report(res: dict[str, Any]) -> str:
    lines = [
        f"Particle filter update in the map of {res['map']} ({res['cells'][0]}x{res['cells'][1]} cells), "
        f"its real scans, {res['beams']} beams asked ({res['rows'][0]['beams_used']} valid ones used), one core:",
        "",
        "| particles | update ms (tracking) | Hz | weighting ms | weighting ms, particles spread over the map | Hz spread | numpy weighting ms | speed-up |",
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in res["rows"]:
        lines.append(
            f"| {r['particles']:,} | {r['update_ms']} | {r['hz']} | {r['weighting_ms']} | "
            f"{r['weighting_spread_ms']} | {r['hz_spread']} | {r['numpy_weighting_ms']} | {r['speedup_vs_numpy']}× |"
        )
    t = res["target"]
    lines += [
        "",
        f"Target 10,000 particles at ≥ 10 Hz: {t['hz']} Hz with the particles gathered, {t['hz_spread']} Hz "
        f"spread over the map ({'met' if t['met'] else 'missed'}).",
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.bench_localization", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the real data folder")
    ap.add_argument("--beams", type=int, default=180, help="beams per scan (default 180)")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    emit_result(args, run(args.data, args.beams), report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
