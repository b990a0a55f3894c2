"""Measurements of the topological-map chain (book Sects. 4.5, 4.7) on the real IPA data.

1. **Relaxation, leave one building out** (``topology_lobo.{json,md}``): for each of the five
   labelled buildings, train a place model on the other four (room, corridor, doorway; stride
   4; T = 100), label every free cell of the fifth, relax with the training maps' statistics
   (saved in the model), correct the regions with the thresholds derived from the training
   maps, and score every labelled free cell before relaxation, after it, and after the
   correction (3 classes). The book: 97.27 % → 98.95 %.
2. **Room segmentation** (``topology_segmentation.{json,md}``): the 16 maps of
   ``ipa/segmentation``, with and without furniture, scored against the same
   ``_gt_segmentation.png``. Free = grey >= 250. The segments are the regions labelled room,
   corridor or hallway, the other free cells grown into them. Models, never trained on the
   building they score:

   * ``real``: for a map of one of the labelled buildings (Freiburg52_scan = Fr52, lab_d_scan =
     lab_d_furnitures, lab_intel, lab_ipa, office_e), the leave-one-out model of part 1 that
     was trained without it; for the other eleven maps, a model trained on all five labelled
     buildings;
   * ``synthetic``: by default the bundled map model knowledge/places/models/default_map.npz
     (``--synthetic-model`` names another; it was a model of generated buildings only before the
     bundled models were trained on the real maps too, see docs/places.md).

   Published (AdaBoost method of ipa_room_segmentation, Bormann et al. 2016): recall 89.2 % /
   precision 90.4 % without furniture, 85.1 % / 87.1 % with, 269 s per map.

Models are cached in ``--models`` (retrained when the cached one was made with other settings).
Histograms can be cached too (``--cache-histograms``) to try the post-processing again without
relabeling; the timings then come from the run that labelled.

Run: ``python -m tools.evaluate_topology --out docs/results`` (about an hour on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from agent.datasets import data_dir
from agent.progress import Progress
from knowledge.fileio import atomic_write_bytes, atomic_write_text, write_image
from knowledge.labels import DOORWAY
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.dataset import IPA_BUILDINGS, LabelledMap, load_ipa_building
from knowledge.places.labeling import MapLabels, class_codes, label_map
from knowledge.places.model import PlaceModel, default_map_model_path
from knowledge.places.regions import correct_regions
from knowledge.places.training import TrainingConfig, train_place_model
from knowledge.topology.pipeline import (
    TopologyConfig,
    TopologyResult,
    histogram_image,
    model_relaxation_stats,
    model_thresholds,
    topology_from_histograms,
)
from knowledge.topology.segmentation_score import gt_rooms, score
from knowledge.topology.topomap import draw_graph, draw_labels, draw_regions, map_background, overview

CLASSES3 = ("room", "corridor", "doorway")
SEG_MAPS = (
    "Freiburg52_scan",
    "Freiburg79_scan",
    "lab_a_scan",
    "lab_b_scan",
    "lab_d_scan",
    "lab_f_scan",
    "lab_intel",
    "lab_ipa",
    "office_a",
    "office_b",
    "office_c",
    "office_d",
    "office_e",
    "office_f",
    "office_g",
    "office_i",
)
#: Segmentation maps that show one of the labelled buildings.
SAME_BUILDING = {
    "Freiburg52_scan": "Fr52",
    "lab_d_scan": "lab_d_furnitures",
    "lab_intel": "lab_intel",
    "lab_ipa": "lab_ipa",
    "office_e": "office_e",
}
#: ipa_room_segmentation's AdaBoost ("semantic") method, Bormann et al., ICRA 2016.
PUBLISHED: dict[str, dict[str, float]] = {
    "plain": {"recall": 0.892, "precision": 0.904},
    "furniture": {"recall": 0.851, "precision": 0.871},
}
PUBLISHED_SECONDS_PER_MAP = 269.0
FREE_GREY = 250
RESOLUTION = 0.05
#: Post-processing variants scored from the same histograms (the last is the pipeline's default).
VARIANTS: dict[str, TopologyConfig] = {
    "labels": TopologyConfig(iterations=0, correct=False, grow_segments=False),
    "relaxed": TopologyConfig(correct=False, grow_segments=False),
    "relaxed+corrected": TopologyConfig(grow_segments=False),
    "relaxed+corrected+grown": TopologyConfig(),
}
FINAL = "relaxed+corrected+grown"


# ---------------------------------------------------------------------- models
def cached_model(
    path: Path,
    train: Sequence[LabelledMap],
    config: TrainingConfig,
    progress: Callable[[str, int, int], None],
) -> tuple[PlaceModel, float | None]:
    """The model at ``path`` if it was trained on ``train`` with ``config``; else train and save it."""
    names = [m.name for m in train]
    if path.is_file():
        model = PlaceModel.load(path)
        same = list(model.data.maps) == names and model.data.notes.get("config") == config.as_json()
        if same and "correction" in model.extras_meta:
            return model, None
    print(f"training {path.name} on {', '.join(names)} ...", file=sys.stderr, flush=True)
    model, timings = train_place_model(train, config, progress=progress)
    model.save(path)
    return model, timings["total"]


# ---------------------------------------------------------------------- histograms
def labelled_histograms(
    grid: OccupancyGrid,
    model: PlaceModel,
    cache: Path | None,
    progress: Callable[[str, int, int], None],
) -> tuple[MapLabels, float]:
    """Label every free cell (or reuse a cache made by the same model file); returns seconds."""
    key = f"{model.data.date}|{','.join(model.data.maps)}|{int(grid.free.sum())}"
    if cache is not None and cache.is_file():
        with np.load(cache, allow_pickle=False) as d:
            if str(d["key"]) == key:
                classes = tuple(str(c) for c in d["classes"])
                labels = np.zeros(grid.shape, np.uint8)
                ml = MapLabels(
                    labels, d["cells"], d["proba"].astype(np.float32), classes, class_codes(classes)
                )
                return ml, float(d["seconds"])
    t0 = time.perf_counter()
    ml = label_map(grid, model, progress=progress)
    seconds = time.perf_counter() - t0
    if cache is not None:
        import io

        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            key=np.array(key),
            cells=ml.cells.astype(np.int32),
            proba=ml.proba.astype(np.float16),
            classes=np.array(ml.classes),
            seconds=np.array(seconds),
        )
        atomic_write_bytes(cache, buf.getvalue())
    return ml, seconds


# ---------------------------------------------------------------------- part 1
def _acc(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    return float(np.mean(pred[mask] == truth[mask]))


def lobo_row(lmap: LabelledMap, model: PlaceModel, r: TopologyResult) -> dict[str, Any]:
    """Accuracies before/after relaxation and correction, and what each step fixed and broke."""
    truth = lmap.labels
    mask = lmap.grid.free & (truth > 0)
    ok0, ok1, ok2 = (r.initial == truth) & mask, (r.relaxed == truth) & mask, (r.corrected == truth) & mask
    th = r.thresholds
    assert th is not None
    gt_corrected, gt_merges = correct_regions(truth, lmap.grid.resolution, th)
    reasons: dict[str, int] = {}
    for m in r.merges:
        key = "doorway with 1 neighbour" if m.reason.startswith("doorway with") else m.reason
        reasons[key] = reasons.get(key, 0) + 1
    return {
        "building": lmap.name,
        "cells": int(mask.sum()),
        "accuracy_labels": _acc(r.initial, truth, mask),
        "accuracy_relaxed": _acc(r.relaxed, truth, mask),
        "accuracy_corrected": _acc(r.corrected, truth, mask),
        "relaxation_fixed": int(np.sum(ok1 & ~ok0)),
        "relaxation_broke": int(np.sum(ok0 & ~ok1)),
        "correction_fixed": int(np.sum(ok2 & ~ok1)),
        "correction_broke": int(np.sum(ok1 & ~ok2)),
        "merges": len(r.merges),
        "merges_by_reason": reasons,
        "doorway_cells_merged_away": int(np.sum((r.relaxed == DOORWAY) & (r.corrected != DOORWAY) & mask)),
        "true_doorway_cells_merged_away": int(
            np.sum((r.relaxed == DOORWAY) & (r.corrected != DOORWAY) & (truth == DOORWAY) & mask)
        ),
        "regions": len(r.graph.regions),
        "thresholds": th.to_dict(),
        "thresholds_source": r.thresholds_source,
        "ground_truth_corrected_accuracy": _acc(gt_corrected, truth, mask),
        "ground_truth_merges": [
            {"reason": m.reason, "cells": m.cells, "from": m.label_from, "to": m.label_to} for m in gt_merges
        ],
        "order": list(model.decision_list.order_),
        "timings_s": {k: round(float(v), 3) for k, v in r.timings.items()},
    }


def run_lobo(
    maps: dict[str, LabelledMap],
    held_out: Sequence[str],
    models_dir: Path,
    config: TrainingConfig,
    out: Path,
    hist_dir: Path | None,
    progress: Callable[[str, int, int], None],
) -> list[dict[str, Any]]:
    rows = []
    for b in held_out:
        train = [m for name, m in maps.items() if name != b]
        model, train_s = cached_model(models_dir / f"lobo_without_{b}.npz", train, config, progress)
        stats = model_relaxation_stats(model)
        ml, label_s = labelled_histograms(
            maps[b].grid, model, None if hist_dir is None else hist_dir / f"lobo__{b}.npz", progress
        )
        r = topology_from_histograms(
            maps[b].grid,
            histogram_image(ml, stats),
            stats,
            TopologyConfig(),
            fallback_thresholds=model_thresholds(model),
            label_seconds=label_s,
        )
        row = lobo_row(maps[b], model, r)
        row["train_seconds"] = train_s
        rows.append(row)
        bg = map_background(maps[b].grid)
        pic = overview(
            [
                ("labels", draw_labels(bg, r.initial)),
                ("relaxed", draw_labels(bg, r.relaxed)),
                ("relaxed + corrected", draw_labels(bg, r.corrected)),
                ("truth", draw_labels(bg, maps[b].labels)),
            ],
            max_side=640,
        )
        write_image(out / f"topology_lobo_{b}.png", pic)
        print(
            f"[{b}] {100 * row['accuracy_labels']:.2f} % -> relaxed {100 * row['accuracy_relaxed']:.2f} % "
            f"-> corrected {100 * row['accuracy_corrected']:.2f} %",
            file=sys.stderr,
            flush=True,
        )
    return rows


def lobo_markdown(rows: list[dict[str, Any]]) -> list[str]:
    out = [
        "| building | cells | labels | relaxed | relaxed + corrected | relaxation fixed / broke | "
        "correction fixed / broke | merges | truth after correction |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        out.append(
            f"| {r['building']} | {r['cells']:,} | {100 * r['accuracy_labels']:.2f} % | "
            f"{100 * r['accuracy_relaxed']:.2f} % | **{100 * r['accuracy_corrected']:.2f} %** | "
            f"{r['relaxation_fixed']:,} / {r['relaxation_broke']:,} | {r['correction_fixed']:,} / "
            f"{r['correction_broke']:,} | {r['merges']} | {100 * r['ground_truth_corrected_accuracy']:.2f} % |"
        )
    mean = {
        k: float(np.mean([r[k] for r in rows]))
        for k in ("accuracy_labels", "accuracy_relaxed", "accuracy_corrected")
    }
    cells = sum(r["cells"] for r in rows)
    pooled = {
        k: sum(r[k] * r["cells"] for r in rows) / cells
        for k in ("accuracy_labels", "accuracy_relaxed", "accuracy_corrected")
    }
    out.append(
        f"| **mean** | | {100 * mean['accuracy_labels']:.2f} % | {100 * mean['accuracy_relaxed']:.2f} % | "
        f"**{100 * mean['accuracy_corrected']:.2f} %** | | | | |"
    )
    out.append(
        f"| all cells | {cells:,} | {100 * pooled['accuracy_labels']:.2f} % | {100 * pooled['accuracy_relaxed']:.2f} % | "
        f"{100 * pooled['accuracy_corrected']:.2f} % | | | | |"
    )
    return out


# ---------------------------------------------------------------------- part 2
def segmentation_grid(path: Path) -> OccupancyGrid:
    """The map of a segmentation picture: grey >= 250 free, everything else occupied."""
    grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if grey is None:
        raise FileNotFoundError(f"{path}: cannot read the map")
    return OccupancyGrid.from_masks(grey < FREE_GREY, RESOLUTION, name=path.stem)


def _pooled_sums(s: dict[str, Any]) -> tuple[float, int, float, int]:
    rec = np.asarray(s["room_recall"]) * np.asarray(s["room_px"])
    pre = np.asarray(s["segment_precision"]) * np.asarray(s["segment_px"])
    return float(rec.sum()), int(np.sum(s["room_px"])), float(pre.sum()), int(np.sum(s["segment_px"]))


def run_segmentation(
    data: Path,
    schemes: dict[str, Callable[[str], tuple[str, PlaceModel]]],
    maps: Sequence[str],
    out: Path,
    hist_dir: Path | None,
    pictures: Sequence[str],
    progress: Callable[[str, int, int], None],
) -> list[dict[str, Any]]:
    seg_dir = data / "ipa" / "segmentation"
    rows: list[dict[str, Any]] = []
    for scheme, pick in schemes.items():
        for name in maps:
            gt_path = seg_dir / f"{name}_gt_segmentation.png"
            gt_read = cv2.imread(str(gt_path), cv2.IMREAD_UNCHANGED)
            if gt_read is None:
                raise FileNotFoundError(f"{gt_path}: cannot read the ground truth")
            gt: np.ndarray = gt_read
            for variant, stem in (("plain", name), ("furniture", f"{name}_furnitures")):
                grid = segmentation_grid(seg_dir / f"{stem}.png")
                model_name, model = pick(name)
                stats = model_relaxation_stats(model, source=model_name)
                ml, label_s = labelled_histograms(
                    grid, model, None if hist_dir is None else hist_dir / f"{scheme}__{stem}.npz", progress
                )
                P0 = histogram_image(ml, stats)
                th = model_thresholds(model)
                row: dict[str, Any] = {
                    "scheme": scheme,
                    "map": name,
                    "variant": variant,
                    "model": model_name,
                    "free_cells": int(grid.free.sum()),
                    "variants": {},
                }
                for vname, cfg in VARIANTS.items():
                    r = topology_from_histograms(
                        grid, P0, stats, cfg, fallback_thresholds=th, label_seconds=label_s
                    )
                    s = score(r.segments, gt)
                    rec, rpx, pre, spx = _pooled_sums(s)
                    row["variants"][vname] = {
                        **{
                            k: s[k]
                            for k in ("recall_mean", "precision_mean", "recall_pooled", "precision_pooled")
                        },
                        "rooms": s["rooms"],
                        "segments": s["segments"],
                        "sums": [rec, rpx, pre, spx],
                        "timings_s": {k: round(float(v), 3) for k, v in r.timings.items()},
                    }
                    if vname == FINAL:
                        row.update(
                            {
                                k: row["variants"][vname][k]
                                for k in (
                                    "recall_mean",
                                    "precision_mean",
                                    "recall_pooled",
                                    "precision_pooled",
                                    "rooms",
                                    "segments",
                                )
                            }
                        )
                        row["timings_s"] = row["variants"][vname]["timings_s"]
                        row["seconds"] = r.timings["total"]
                        row["regions"] = len(r.graph.regions)
                        row["merges"] = len(r.merges)
                        if stem in pictures:
                            _segmentation_picture(out / f"topology_seg_{scheme}_{stem}.png", grid, gt, r)
                rows.append(row)
                print(
                    f"[{scheme} {stem}] recall {100 * row['recall_mean']:.1f} %, precision "
                    f"{100 * row['precision_mean']:.1f} %, {row['seconds']:.1f} s",
                    file=sys.stderr,
                    flush=True,
                )
    return rows


def _segmentation_picture(path: Path, grid: OccupancyGrid, gt: np.ndarray, r: TopologyResult) -> None:
    from knowledge.places.regions import RegionGraph
    from knowledge.topology.topomap import region_colours

    bg = map_background(grid)
    rooms = gt_rooms(gt)
    room_pic = region_colours(int(rooms.max()))[rooms]
    room_pic[rooms == 0] = np.repeat(bg[rooms == 0, None] // 2, 3, axis=1)
    seg_graph = RegionGraph(r.segments, r.graph.regions, (), r.graph.resolution)
    write_image(
        path,
        overview(
            [
                ("ground-truth rooms", room_pic),
                ("segments", draw_regions(seg_graph, bg)),
                ("relaxed + corrected labels", draw_labels(bg, r.corrected)),
                ("region graph", draw_graph(r.graph, bg)),
            ],
            max_side=700,
        ),
    )


def segmentation_summary(rows: list[dict[str, Any]], variant_name: str = FINAL) -> dict[str, Any]:
    """Averages per scheme and map variant: mean over maps of the per-map means, and pooled."""
    out: dict[str, Any] = {}
    for scheme in sorted({r["scheme"] for r in rows}):
        out[scheme] = {}
        for variant in ("plain", "furniture"):
            sel = [r for r in rows if r["scheme"] == scheme and r["variant"] == variant]
            if not sel:
                continue
            v = [r["variants"][variant_name] for r in sel]
            sums = np.sum([x["sums"] for x in v], axis=0)
            out[scheme][variant] = {
                "maps": len(sel),
                "recall_mean": float(np.mean([x["recall_mean"] for x in v])),
                "precision_mean": float(np.mean([x["precision_mean"] for x in v])),
                "recall_pooled_per_map": float(np.mean([x["recall_pooled"] for x in v])),
                "precision_pooled_per_map": float(np.mean([x["precision_pooled"] for x in v])),
                "recall_pooled_all": float(sums[0] / sums[1]) if sums[1] else 0.0,
                "precision_pooled_all": float(sums[2] / sums[3]) if sums[3] else 0.0,
                "seconds_per_map": float(np.mean([x["timings_s"]["total"] for x in v])),
                "label_seconds_per_map": float(np.mean([x["timings_s"]["label"] for x in v])),
            }
    return out


def segmentation_markdown(rows: list[dict[str, Any]], summary: dict[str, Any]) -> list[str]:
    md: list[str] = []
    for scheme, groups in summary.items():
        md += [
            f"### Models: {scheme}",
            "",
            "| map | model | free cells | recall (no furn.) | precision (no furn.) | recall (furn.) | "
            "precision (furn.) | pooled R / P (no furn.) | pooled R / P (furn.) | s (no furn. / furn.) |",
            "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
        ]
        by = {(r["map"], r["variant"]): r for r in rows if r["scheme"] == scheme}
        for name in SEG_MAPS:
            p, f = by.get((name, "plain")), by.get((name, "furniture"))
            if p is None or f is None:
                continue
            md.append(
                f"| {name} | {p['model']} | {p['free_cells']:,} | {100 * p['recall_mean']:.1f} | "
                f"{100 * p['precision_mean']:.1f} | {100 * f['recall_mean']:.1f} | {100 * f['precision_mean']:.1f} | "
                f"{100 * p['recall_pooled']:.1f} / {100 * p['precision_pooled']:.1f} | "
                f"{100 * f['recall_pooled']:.1f} / {100 * f['precision_pooled']:.1f} | "
                f"{p['seconds']:.1f} / {f['seconds']:.1f} |"
            )
        md += [
            "",
            "| | recall (mean over rooms) | precision (mean over segments) | recall pooled | precision pooled "
            "| s per map (labeling) |",
            "| --- | ---: | ---: | ---: | ---: | ---: |",
        ]
        for variant, label in (("plain", "without furniture"), ("furniture", "with furniture")):
            g = groups.get(variant)
            if g is None:
                continue
            pub = PUBLISHED[variant]
            md.append(
                f"| **{label}**, {g['maps']} maps | **{100 * g['recall_mean']:.1f} %** | "
                f"**{100 * g['precision_mean']:.1f} %** | {100 * g['recall_pooled_all']:.1f} % | "
                f"{100 * g['precision_pooled_all']:.1f} % | {g['seconds_per_map']:.1f} ({g['label_seconds_per_map']:.1f}) |"
            )
            md.append(
                f"| published AdaBoost, {label} | {100 * pub['recall']:.1f} % | {100 * pub['precision']:.1f} % "
                f"| | | {PUBLISHED_SECONDS_PER_MAP:.0f} |"
            )
        md.append("")
    return md


def ablation_markdown(rows: list[dict[str, Any]]) -> list[str]:
    md = [
        "| models | map variant | " + " | ".join(VARIANTS) + " |",
        "| --- | --- | " + " | ".join("---:" for _ in VARIANTS) + " |",
    ]
    for scheme in sorted({r["scheme"] for r in rows}):
        for variant in ("plain", "furniture"):
            cells = []
            for vname in VARIANTS:
                s = segmentation_summary(rows, vname).get(scheme, {}).get(variant)
                cells.append(
                    "–" if s is None else f"{100 * s['recall_mean']:.1f} / {100 * s['precision_mean']:.1f}"
                )
            md.append(f"| {scheme} | {variant} | " + " | ".join(cells) + " |")
    return md


# ---------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.evaluate_topology", description=(__doc__ or "").split("\n\n")[0]
    )
    ap.add_argument(
        "--data", type=Path, default=None, help="data folder (default $LOCI_DATA or ../shared/data)"
    )
    ap.add_argument(
        "--out", type=Path, default=Path("docs/results"), help="folder for the tables and pictures"
    )
    ap.add_argument(
        "--models", type=Path, default=Path("out/topology_models"), help="cache of the trained models"
    )
    ap.add_argument(
        "--cache-histograms",
        action="store_true",
        help="keep the classifier histograms in MODELS/histograms and reuse them (timings from the labeling run)",
    )
    ap.add_argument("--part", choices=("all", "lobo", "segmentation"), default="all")
    ap.add_argument(
        "--schemes",
        default="real,synthetic",
        help="model schemes for the segmentation: real, synthetic (default both; synthetic when its model exists)",
    )
    ap.add_argument(
        "--synthetic-model",
        type=Path,
        default=None,
        help="the model of the synthetic scheme (default: the bundled knowledge/places/models/default.npz)",
    )
    ap.add_argument("--only", action="append", default=[], help="only these buildings / segmentation maps")
    ap.add_argument("--stride", type=int, default=4, help="training stride in cells (default 4)")
    ap.add_argument("--rounds", type=int, default=100, help="boosting rounds T (default 100)")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    data = args.data or data_dir()
    if not (data / "ipa" / "labeled").is_dir():
        print(f"no labelled maps under {data}/ipa/labeled: pass --data or set LOCI_DATA", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    args.models.mkdir(parents=True, exist_ok=True)
    hist_dir = args.models / "histograms" if args.cache_histograms else None
    if hist_dir is not None:
        hist_dir.mkdir(parents=True, exist_ok=True)
    cmd = "python -m tools.evaluate_topology " + " ".join(argv if argv is not None else sys.argv[1:])
    config = TrainingConfig(stride=args.stride, rounds=args.rounds, classes=CLASSES3)
    maps = {b: load_ipa_building(data, b) for b in IPA_BUILDINGS}
    t_start = time.perf_counter()
    with Progress(enabled=not args.quiet) as progress:
        if args.part in ("all", "lobo"):
            held_out = [b for b in IPA_BUILDINGS if not args.only or b in args.only]
            rows = run_lobo(maps, held_out, args.models, config, args.out, hist_dir, progress)
            doc = {"command": cmd.strip(), "config": config.as_json(), "buildings": rows}
            atomic_write_text(args.out / "topology_lobo.json", json.dumps(doc, indent=2) + "\n")
            md = [
                "# Relaxation labeling and region correction, leave one building out",
                "",
                f"Made by `{doc['command']}` (see docs/topology.md).",
                "",
                f"Train on four buildings (room, corridor, doorway; stride {args.stride}, T = {args.rounds}), label "
                "every free cell of the fifth, relax (50 iterations, the training maps' statistics), correct "
                "the regions (thresholds from the training maps), score every labelled free cell (3 classes). "
                "The book: 97.27 % → 98.95 % (building 79).",
                "",
                *lobo_markdown(rows),
                "",
                '"truth after correction": the correction applied to the hand labels themselves.',
                "",
            ]
            atomic_write_text(args.out / "topology_lobo.md", "\n".join(md))
            print("\n".join(md))
        if args.part in ("all", "segmentation"):
            wanted = [s.strip() for s in args.schemes.split(",") if s.strip()]
            schemes: dict[str, Callable[[str], tuple[str, PlaceModel]]] = {}
            loaded: dict[str, PlaceModel] = {}
            if "real" in wanted:

                def pick_real(name: str) -> tuple[str, PlaceModel]:
                    b = SAME_BUILDING.get(name)
                    if b is None:
                        key, train = "all_five", list(maps.values())
                    else:
                        key, train = f"lobo_without_{b}", [m for n, m in maps.items() if n != b]
                    if key not in loaded:
                        loaded[key], _ = cached_model(args.models / f"{key}.npz", train, config, progress)
                    return key, loaded[key]

                schemes["real"] = pick_real
            synthetic_path: Path = args.synthetic_model or default_map_model_path()
            if "synthetic" in wanted and synthetic_path.is_file():
                synthetic = PlaceModel.load(synthetic_path)
                synthetic_name = "bundled default" if args.synthetic_model is None else synthetic_path.name
                schemes["synthetic"] = lambda name: (synthetic_name, synthetic)
            elif "synthetic" in wanted:
                print(f"no model at {synthetic_path}: skipping the synthetic scheme", file=sys.stderr)
            seg_maps = [m for m in SEG_MAPS if not args.only or m in args.only]
            rows = run_segmentation(
                data, schemes, seg_maps, args.out, hist_dir, ("lab_intel_furnitures", "office_e"), progress
            )
            summary = segmentation_summary(rows)
            doc = {
                "command": cmd.strip(),
                "published": {"scores": PUBLISHED, "seconds_per_map": PUBLISHED_SECONDS_PER_MAP},
                "summary": summary,
                "ablation": {v: segmentation_summary(rows, v) for v in VARIANTS},
                "maps": rows,
            }
            atomic_write_text(args.out / "topology_segmentation.json", json.dumps(doc, indent=2) + "\n")
            md = [
                "# Room segmentation from the topological map",
                "",
                f"Made by `{doc['command']}` (see docs/topology.md).",
                "",
                "Segments: the regions labelled room, corridor or hallway after relaxation and correction, the "
                "other free cells (doorway regions) grown into them. Scored against `_gt_segmentation.png` "
                "(rooms and segments of <= 100 px ignored, segments not clipped). Recall / precision in %: "
                "the mean over rooms / segments of each map, averaged over the maps; pooled: all pixels of all maps. "
                "Seconds per map: labeling + relaxation + correction + regions + segments (labeling alone in brackets).",
                "",
                "Models, never trained on the building they score: *real* = for Freiburg52_scan, lab_d_scan, lab_intel, "
                "lab_ipa and office_e the leave-one-out model trained on the other four labelled IPA buildings "
                "(`lobo_without_<building>`), for the other eleven maps a model trained on all five (`all_five`); "
                "*synthetic* = a model trained on generated buildings only. Training: room, corridor, doorway, "
                "stride 4, T = 100 (real); see the model file for the synthetic one.",
                "",
                *segmentation_markdown(rows, summary),
                "## What each step adds (recall / precision, mean over maps)",
                "",
                *ablation_markdown(rows),
                "",
            ]
            atomic_write_text(args.out / "topology_segmentation.md", "\n".join(md))
            print("\n".join(md))
    print(f"done in {time.perf_counter() - t_start:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
