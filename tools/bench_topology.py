"""Benchmark: relaxation labeling and region extraction + correction on the largest map.

The map is ``office_g`` of the IPA segmentation set (2314 × 2050 cells, ≈1.14 M free at
0.05 m). The initial histograms are real classifier output when a place model is given
(``--model``; by default the bundled model when it exists): every free cell is labelled
(timed too), and the model's saved statistics drive the relaxation. Without a model
(``--synthetic``, or no bundled model) a quick geometric heuristic labels the free cells (long
thin free runs → corridor, narrow passages → doorway, the rest room), the initial histograms
are that labelling made noisy (each cell's one-hot blurred with Dirichlet noise, 15 % of the
cells confidently wrong), and the heuristic labelling also trains the compatibilities.

Steps timed: compatibility statistics, relaxation (50 iterations, OpenCV backend; the plain
numpy backend as the in-process baseline), argmax, heuristic correction, region extraction
with the graph, the JSON document and the pictures. Peak memory is traced per step
(``tracemalloc``: numpy and OpenCV output arrays; OpenCV's internal buffers are not seen) and the
process's peak resident size is reported at the end.

    python -m tools.bench_topology [--map PATH] [--model M | --synthetic] [--iterations 50]
                                         [--no-baseline] [--json | --json-file OUT]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from agent.datasets import data_dir
from knowledge.labels import CORRIDOR, DOORWAY, ROOM
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.labeling import label_map
from knowledge.places.model import PlaceModel, default_map_model_path
from knowledge.places.regions import CorrectionThresholds, correct_regions, extract_regions
from knowledge.places.relaxation import CompatibilityStats, argmax_labels, relax
from knowledge.topology.pipeline import (
    histogram_image,
    model_relaxation_stats,
    model_thresholds,
    segments_from_regions,
)
from knowledge.topology.segmentation_score import score
from knowledge.topology.topomap import draw_graph, draw_regions, dumps, map_background, topomap_document

DEFAULT_MAP = data_dir() / "ipa" / "segmentation" / "office_g.png"
RESOLUTION = 0.05
CLASSES = (ROOM, CORRIDOR, DOORWAY)

T = TypeVar("T")


def heuristic_labels(free: np.ndarray, resolution: float) -> np.ndarray:
    """A rough place labelling from free-space runs (a stand-in for the classifier).

    Corridor: cells on a free run of at least 8 m along one axis and at most 3 m along the
    other. Doorway: cells whose free runs are shorter than 1.1 m along one axis but longer
    than 2 m along the other (a gap in a wall). Room: every other free cell.
    """
    f = free.astype(np.uint8)

    def runs(length_m: float, horizontal: bool) -> np.ndarray:
        n = max(1, round(length_m / resolution))
        k = np.ones((1, n) if horizontal else (n, 1), np.uint8)
        return cv2.morphologyEx(f, cv2.MORPH_OPEN, k).astype(bool)

    long_h, long_v = runs(8.0, True), runs(8.0, False)
    wide_h, wide_v = runs(3.0, True), runs(3.0, False)
    door_h, door_v = runs(1.1, True), runs(1.1, False)
    mid_h, mid_v = runs(2.0, True), runs(2.0, False)
    lab = np.where(free, ROOM, 0).astype(np.uint8)
    lab[(long_h & ~wide_v) | (long_v & ~wide_h)] = CORRIDOR
    lab[free & ((~door_h & mid_v) | (~door_v & mid_h))] = DOORWAY
    return lab


def noisy_histograms(
    truth: np.ndarray, free: np.ndarray, *, wrong: float = 0.15, seed: int = 0
) -> np.ndarray:
    """``(rows, cols, 4)`` float32 histograms (room, corridor, doorway, wall) around ``truth``."""
    rng = np.random.default_rng(seed)
    col = np.zeros(256, np.int64)
    col[CORRIDOR], col[DOORWAY] = 1, 2
    idx = col[truth]
    P = np.zeros((*truth.shape, 4), np.float32)
    noise = rng.dirichlet([1.0, 1.0, 1.0], size=int(free.sum())).astype(np.float32)
    P[free, :3] = 0.55 * np.eye(3, dtype=np.float32)[idx[free]] + 0.45 * noise
    flip = free & (rng.random(truth.shape) < wrong)
    P[flip, :3] = np.eye(3, dtype=np.float32)[rng.integers(0, 3, int(flip.sum()))] * 0.7 + 0.1
    return P


def _timed(result: dict[str, Any], name: str, fn: Callable[[], T]) -> T:
    tracemalloc.start()
    t0 = time.perf_counter()
    out = fn()
    result[f"{name}_s"] = round(time.perf_counter() - t0, 4)
    result[f"{name}_peak_mb"] = round(tracemalloc.get_traced_memory()[1] / 1e6, 1)
    tracemalloc.stop()
    return out


def run(
    map_path: Path | None = None,
    *,
    iterations: int = 50,
    baseline: bool = True,
    model: PlaceModel | None = None,
    model_name: str = "",
) -> dict[str, Any]:
    """Time every step on ``map_path`` (office_g by default); returns seconds, MB and counts.

    With ``model`` the histograms are the model's output on every free cell; otherwise they
    are synthetic (see the module doc).
    """
    path = Path(map_path or DEFAULT_MAP)
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise FileNotFoundError(f"{path}: cannot read the map (is ../shared/data present?)")
    free = image >= 250
    grid = OccupancyGrid.from_masks(~free, RESOLUTION, name=path.stem)
    r: dict[str, Any] = {
        "map": path.stem,
        "rows": grid.shape[0],
        "cols": grid.shape[1],
        "free_cells": int(free.sum()),
        "iterations": iterations,
        "histograms": f"classifier ({model_name})" if model is not None else "synthetic",
    }
    truth: np.ndarray | None
    if model is not None:
        ml = _timed(r, "label", lambda: label_map(grid, model))
        stats = model_relaxation_stats(model, source=model_name)
        th, r["thresholds_source"] = model_thresholds(model)
        P0 = histogram_image(ml, stats)
        del ml
        truth = None
    else:
        truth = heuristic_labels(free, RESOLUTION)
        P0 = noisy_histograms(truth, free)
        t = truth
        stats = _timed(r, "stats", lambda: CompatibilityStats.from_label_images([(t, ~free)], CLASSES))
        th, r["thresholds_source"] = CorrectionThresholds(), "book"
    P = _timed(r, "relax", lambda: relax(P0, stats, free_mask=free, iterations=iterations, backend="cv2"))
    r["relax_per_iteration_ms"] = round(1000 * r["relax_s"] / max(iterations, 1), 2)
    tiny = P[free, :3]
    r["denormal_fraction"] = float(np.mean((tiny > 0) & (tiny < np.finfo(np.float32).tiny)))
    if baseline:
        Pn = _timed(
            r, "relax_numpy", lambda: relax(P0, stats, free_mask=free, iterations=iterations, backend="numpy")
        )
        r["relax_speedup_vs_numpy"] = round(r["relax_numpy_s"] / r["relax_s"], 2)
        r["backends_max_abs_diff"] = float(np.abs(Pn - P).max())
        del Pn
    before = argmax_labels(P0, stats, free)
    after = _timed(r, "argmax", lambda: argmax_labels(P, stats))
    r["relaxation_changed_cells"] = int(np.sum((before != after) & free))
    corrected, merges = _timed(r, "correct", lambda: correct_regions(after, RESOLUTION, th))
    r["correction_rounds"] = max((m.round for m in merges), default=0)
    r["merges"] = len(merges)
    graph = _timed(r, "regions", lambda: extract_regions(corrected, grid))
    r["regions"] = len(graph.regions)
    r["edges"] = len(graph.edges)
    text = _timed(r, "document", lambda: dumps(topomap_document(graph, grid, thresholds=th, merges=merges)))
    r["document_kb"] = round(len(text.encode()) / 1e3, 1)
    bg = map_background(grid)
    _timed(r, "pictures", lambda: (draw_regions(graph, bg), draw_graph(graph, bg)))
    if truth is not None:
        r["accuracy_initial"] = round(float((before == truth)[free].mean()), 4)
        r["accuracy_relaxed"] = round(float((after == truth)[free].mean()), 4)
        r["accuracy_corrected"] = round(float((corrected == truth)[free].mean()), 4)
    gt_path = path.with_name(path.stem.removesuffix("_furnitures") + "_gt_segmentation.png")
    gt = cv2.imread(str(gt_path), cv2.IMREAD_UNCHANGED)
    if gt is not None:
        seg = _timed(r, "segments", lambda: segments_from_regions(graph, free))
        sc = score(seg, gt)
        r["segmentation"] = {k: round(float(sc[k]), 4) for k in ("recall_mean", "precision_mean")}
    r["relax_and_regions_s"] = round(r["relax_s"] + r["argmax_s"] + r["correct_s"] + r["regions_s"], 3)
    r["max_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3, 1)
    return r


def format_result(r: dict[str, Any]) -> str:
    lines = [
        f"topology benchmark: {r['map']} {r['rows']}x{r['cols']} cells, {r['free_cells']} free, "
        f"{r['iterations']} relaxation iterations",
    ]
    lines[0] += f"; {r['histograms']} histograms"
    steps = [
        "label",
        "stats",
        "relax",
        "relax_numpy",
        "argmax",
        "correct",
        "regions",
        "segments",
        "document",
        "pictures",
    ]
    for s in steps:
        if f"{s}_s" in r:
            lines.append(f"  {s:12s} {r[f'{s}_s']:8.3f} s   peak {r[f'{s}_peak_mb']:7.1f} MB")
    lines.append(f"  relaxation {r['relax_per_iteration_ms']:.1f} ms per iteration")
    if "relax_speedup_vs_numpy" in r:
        lines.append(
            f"  OpenCV backend {r['relax_speedup_vs_numpy']:.2f}x the numpy backend "
            f"(max difference {r['backends_max_abs_diff']:.1e})"
        )
    lines.append(
        f"  correction: {r['merges']} merges in {r['correction_rounds']} rounds -> {r['regions']} regions, "
        f"{r['edges']} edges, document {r['document_kb']} kB"
    )
    lines.append(f"  relaxation changed {r['relaxation_changed_cells']} cells")
    if "accuracy_initial" in r:
        lines.append(
            f"  agreement with the heuristic labels: initial {100 * r['accuracy_initial']:.2f} %, "
            f"relaxed {100 * r['accuracy_relaxed']:.2f} %, corrected {100 * r['accuracy_corrected']:.2f} %"
        )
    if "segmentation" in r:
        seg = r["segmentation"]
        lines.append(
            f"  room segmentation: recall {100 * seg['recall_mean']:.1f} %, precision {100 * seg['precision_mean']:.1f} %"
        )
    lines.append(
        f"  relaxation + regions {r['relax_and_regions_s']:.2f} s; peak RSS {r['max_rss_mb']:.0f} MB"
    )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    doc = (__doc__ or "").split("\n")[0]
    parser = argparse.ArgumentParser(prog="python -m tools.bench_topology", description=doc)
    parser.add_argument("--map", type=Path, default=None, help=f"map image (default: {DEFAULT_MAP})")
    parser.add_argument(
        "--model", type=Path, default=None, help="place model for real histograms (default: the bundled one)"
    )
    parser.add_argument("--synthetic", action="store_true", help="synthetic histograms, no classifier")
    parser.add_argument("--iterations", type=int, default=50)
    parser.add_argument("--no-baseline", action="store_true", help="skip the numpy backend")
    add_json_option(parser)
    add_json_file_option(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    model, name = None, ""
    if not args.synthetic:
        path = args.model or default_map_model_path()
        if path.is_file():
            model, name = PlaceModel.load(path), path.name
        elif args.model is not None:
            parser.error(f"{path}: no such model file")
        else:
            print(f"no bundled model at {path}: synthetic histograms", file=sys.stderr)
    r = run(args.map, iterations=args.iterations, baseline=not args.no_baseline, model=model, model_name=name)
    cmd = "python -m tools.bench_topology " + " ".join(argv if argv is not None else sys.argv[1:])
    emit_result(args, {"command": cmd.strip(), **r}, format_result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
