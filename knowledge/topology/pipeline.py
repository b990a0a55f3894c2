"""From an occupancy grid and a place model to a topological map (book Sects. 4.5 and 4.7).

The chain, every step kept in the result::

    grid ──label_map()──> P0 (N, K) ──relax()──> P ──argmax──> relaxed labels
         ──correct_regions()──> corrected labels ──extract_regions()──> region graph
         ──segments_from_regions()──> room segments

* **Histograms** come from the model's probabilistic decision list (eq. 4.5) for every free
  cell (:func:`knowledge.places.labeling.label_map`), or from the caller
  (:func:`topology_from_histograms`, e.g. histograms computed earlier).
* **Relaxation** uses the label statistics of the training maps that the model file carries
  (:func:`model_relaxation_stats`; saved by ``loci places train``).
* **Correction thresholds** come from the configuration, else from the model file (derived from
  the training maps' true regions at training time, :func:`model_thresholds`), else the book's
  1 m² and 0.1 m².
* **Segments** (for room-segmentation scores): the regions labelled room, corridor or hallway.
  With ``grow_segments`` (the default) the free cells outside them (doorway regions, specks
  the correction could not merge) join the nearest segment, by a wavefront that spreads
  through free space only, so the segments tile the free space, as a room segmentation does.
  Each segment keeps its region id.

Everything is in memory; the caller writes files. Timings are in seconds.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from knowledge import labels as lbl
from knowledge.errors import ModelError
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.labeling import MapLabels, label_map
from knowledge.places.model import PlaceModel
from knowledge.places.regions import (
    CorrectionThresholds,
    Merge,
    RegionGraph,
    correct_regions,
    extract_regions,
)
from knowledge.places.relaxation import Border, CompatibilityStats, argmax_labels, relax
from knowledge.topology.topomap import topomap_document

ProgressFn = Callable[[str, int, int], None]
"""``progress(stage, done, total)``."""

#: The label codes whose regions are room segments.
SEGMENT_CODES: tuple[int, ...] = (lbl.ROOM, lbl.CORRIDOR, lbl.HALLWAY)

#: Where the model file keeps the relaxation statistics (:meth:`CompatibilityStats.to_arrays`).
STATS_PREFIX = "relaxation_"
#: ``extras_meta`` key of the correction thresholds saved at training time.
THRESHOLDS_META = "correction"

_RETRAIN = (
    "retrain it with this genius-loci (e.g. `loci places train --ipa all --classes room,corridor,doorway "
    "--out MODEL.npz`), which saves them"
)


@dataclass(frozen=True)
class TopologyConfig:
    """Settings of the chain.

    Attributes:
        iterations: relaxation iterations (the book: 50); 0 skips relaxation.
        o: the neighbour weight ``o_ij`` of eq. 4.7, in ``(0, 1/8]``.
        border: what a neighbour outside the map is during relaxation ("wall" or "none").
        correct: apply the heuristic region correction of Sect. 4.7.
        thresholds: correction thresholds; None = the model's (saved at training), else the book's.
        connectivity: 8 (the book) or 4, for regions and the graph.
        grow_segments: let the segments fill the free cells outside them (see the module doc).
        segment_codes: label codes whose regions are segments.
    """

    iterations: int = 50
    o: float = 1.0 / 8.0
    border: Border = "wall"
    correct: bool = True
    thresholds: CorrectionThresholds | None = None
    connectivity: int = 8
    grow_segments: bool = True
    segment_codes: tuple[int, ...] = SEGMENT_CODES

    def __post_init__(self) -> None:
        if int(self.iterations) != self.iterations or self.iterations < 0:
            raise ValueError(f"iterations must be a non-negative integer, got {self.iterations}")
        if self.connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 8 or 4, got {self.connectivity}")
        if self.border not in ("wall", "none"):
            raise ValueError(f"border must be 'wall' or 'none', got {self.border!r}")


@dataclass(frozen=True, eq=False)
class TopologyResult:
    """Every intermediate result of the chain for one map.

    Attributes:
        grid: the map.
        stats: the compatibilities used; ``stats.classes`` are the label codes of the place
            classes, in the column order of ``relaxed_proba``.
        class_names: label code → class name.
        initial: ``(rows, cols)`` uint8 label codes before relaxation (0 off free cells).
        relaxed_proba: ``(rows, cols, K)`` float32 relaxed histograms, wall column last.
        relaxed: ``(rows, cols)`` uint8 label codes after relaxation.
        corrected: ``(rows, cols)`` uint8 label codes after the correction (= ``relaxed``
            when no correction ran).
        merges: what the correction merged.
        thresholds: the correction thresholds used (None when no correction ran).
        thresholds_source: "config", "model" or "book" (or "none").
        graph: regions and region graph of ``corrected``.
        segments: ``(rows, cols)`` int32 room segments (region ids; 0 = none).
        timings: seconds per step: ``label`` (ray casting, classification, histogram image),
            ``relax`` (with both argmax images), ``correct``, ``regions``, ``segments``, ``total``.
        config: the settings used.
        map_labels: the classifier's output when the chain ran it.
        meta: facts for the document's ``meta`` (e.g. the model's classes, free cells).
    """

    grid: OccupancyGrid
    stats: CompatibilityStats
    class_names: Mapping[int, str]
    initial: np.ndarray
    relaxed_proba: np.ndarray
    relaxed: np.ndarray
    corrected: np.ndarray
    merges: tuple[Merge, ...]
    thresholds: CorrectionThresholds | None
    thresholds_source: str
    graph: RegionGraph
    segments: np.ndarray
    timings: Mapping[str, float]
    config: TopologyConfig
    map_labels: MapLabels | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def regions_per_class(self) -> dict[str, int]:
        """Number of regions of each class, in class order."""
        counts = {self.class_names.get(c, f"code{c}"): 0 for c in self.stats.classes}
        for reg in self.graph.regions:
            name = self.class_names.get(reg.label, f"code{reg.label}")
            counts[name] = counts.get(name, 0) + 1
        return counts

    def document(self, meta: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The ``loci.topomap/1`` document (:func:`knowledge.topology.topomap.topomap_document`)."""
        info: dict[str, Any] = {
            "relaxation": {
                "iterations": self.config.iterations,
                "o": self.config.o,
                "border": self.config.border,
                "labels": list(self.stats.label_names),
            },
            "thresholds_source": self.thresholds_source,
            "timings_s": {k: round(float(v), 4) for k, v in self.timings.items()},
            **dict(self.meta),
            **dict(meta or {}),
        }
        return topomap_document(
            self.graph,
            self.grid,
            thresholds=self.thresholds,
            merges=self.merges,
            class_names=self.class_names,
            meta=info,
        )


# ---------------------------------------------------------------------- the model's parts
def model_relaxation_stats(model: PlaceModel, *, source: str = "the model") -> CompatibilityStats:
    """The relaxation compatibilities saved in a model file at training time.

    Raises:
        ModelError: the model has none (trained before they were saved), or they do not match
            the model's classes; the message says how to retrain.
    """
    if f"{STATS_PREFIX}counts" not in model.extras:
        raise ModelError(
            f"{source} has no relaxation statistics (label statistics of its training maps, eq. 4.8); "
            + _RETRAIN
        )
    try:
        stats = CompatibilityStats.from_arrays(model.extras, prefix=STATS_PREFIX)
    except ValueError as exc:
        raise ModelError(f"{source}: its relaxation statistics are damaged ({exc}); " + _RETRAIN) from exc
    codes = model_class_codes(model)
    missing = [name for name, code in codes.items() if code not in stats.classes]
    if missing or len(stats.classes) != len(codes):
        raise ModelError(
            f"{source}: its relaxation statistics cover label codes {list(stats.classes)} but the classifier "
            f"has classes {list(model.classes)}; " + _RETRAIN
        )
    return stats


def model_class_codes(model: PlaceModel) -> dict[str, int]:
    """Class name → label code of a model's classes (standard codes; relaxation needs them)."""
    out: dict[str, int] = {}
    for name in model.classes:
        if name not in lbl.CLASS_CODES:
            raise ModelError(
                f"the model's class {name!r} has no standard label code; relaxation and regions work on "
                f"{', '.join(lbl.CLASS_CODES)}"
            )
        out[name] = lbl.CLASS_CODES[name]
    return out


def model_thresholds(model: PlaceModel) -> tuple[CorrectionThresholds, str]:
    """The correction thresholds saved at training time, or the book's defaults.

    Returns:
        ``(thresholds, source)`` with source "model" or "book".
    """
    entry = model.extras_meta.get(THRESHOLDS_META)
    if isinstance(entry, Mapping) and isinstance(entry.get("thresholds"), Mapping):
        try:
            return CorrectionThresholds.from_dict(entry["thresholds"]), "model"
        except (ValueError, TypeError) as exc:
            raise ModelError(f"the model's correction thresholds are invalid ({exc}); " + _RETRAIN) from exc
    return CorrectionThresholds(), "book"


def histogram_image(map_labels: MapLabels, stats: CompatibilityStats) -> np.ndarray:
    """``(rows, cols, K-1)`` float32 classifier histograms in ``stats.classes`` column order."""
    col_of_code = {code: i for i, code in enumerate(stats.classes)}
    P = np.zeros((*map_labels.labels.shape, len(stats.classes)), dtype=np.float32)
    cells = map_labels.cells
    for j, name in enumerate(map_labels.classes):
        code = map_labels.codes[name]
        if code not in col_of_code:
            raise ValueError(
                f"class {name!r} (code {code}) is not among the relaxation classes {list(stats.classes)}"
            )
        P[cells[:, 0], cells[:, 1], col_of_code[code]] = map_labels.proba[:, j]
    return P


# ---------------------------------------------------------------------- segments
def segments_from_regions(
    graph: RegionGraph,
    free: np.ndarray,
    *,
    codes: Sequence[int] = SEGMENT_CODES,
    grow: bool = True,
    connectivity: int | None = None,
) -> np.ndarray:
    """``(rows, cols)`` int32 room segments: ids of the regions whose label is in ``codes``.

    With ``grow``, every other free cell that free space connects to a segment takes the id
    of the segment its wavefront reaches first (steps to 8-neighbours, or 4-neighbours with
    ``connectivity=4``; default: the graph's connectivity; where two fronts arrive in the same
    step, the higher id wins). Cells never reached (free space without any segment) stay 0.
    """
    wanted = np.zeros(max([0, *codes, *(r.label for r in graph.regions)]) + 1, dtype=bool)
    wanted[list(codes)] = True
    lut = np.zeros(len(graph.regions) + 1, dtype=np.int32)
    for reg in graph.regions:
        if wanted[reg.label]:
            lut[reg.id] = reg.id
    seg = lut[graph.ids]
    if not grow:
        return seg
    free_mask = np.asarray(free, dtype=bool)
    if free_mask.shape != seg.shape:
        raise ValueError(f"free mask {free_mask.shape} and regions {seg.shape} differ in shape")
    todo = free_mask & (seg == 0)
    if not todo.any() or not seg.any():
        return seg
    if len(graph.regions) > 65535:
        raise ValueError("more than 65535 regions cannot be grown (16-bit ids)")
    # work on the bounding box of the cells to fill, one cell wider
    rr = np.flatnonzero(todo.any(axis=1))
    cc = np.flatnonzero(todo.any(axis=0))
    r0, r1 = max(int(rr[0]) - 1, 0), min(int(rr[-1]) + 2, seg.shape[0])
    c0, c1 = max(int(cc[0]) - 1, 0), min(int(cc[-1]) + 2, seg.shape[1])
    box = seg[r0:r1, c0:c1].astype(np.uint16)
    open_ = todo[r0:r1, c0:c1].copy()
    conn = graph.connectivity if connectivity is None else connectivity
    if conn not in (4, 8):
        raise ValueError(f"connectivity must be 8 or 4, got {conn}")
    kernel = np.ones((3, 3), np.uint8) if conn == 8 else cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    while True:
        grown = cv2.dilate(box, kernel)
        take = open_ & (grown > 0)
        if not take.any():
            break
        box[take] = grown[take]
        open_ &= ~take
    seg[r0:r1, c0:c1] = box
    return seg


# ---------------------------------------------------------------------- the chain
def topology_from_histograms(
    grid: OccupancyGrid,
    histograms: np.ndarray,
    stats: CompatibilityStats,
    config: TopologyConfig | None = None,
    *,
    fallback_thresholds: tuple[CorrectionThresholds, str] | None = None,
    class_names: Mapping[int, str] | None = None,
    label_seconds: float = 0.0,
    map_labels: MapLabels | None = None,
    meta: Mapping[str, Any] | None = None,
) -> TopologyResult:
    """Relaxation, correction, regions and segments from classifier histograms.

    Args:
        grid: the map; its free cells are the ones labelled.
        histograms: ``(rows, cols, K-1)`` (or ``(rows, cols, K)`` with a wall column) float
            histograms, columns in ``stats.classes`` order; read on free cells only.
        stats: the compatibilities.
        config: the settings (defaults: :class:`TopologyConfig`).
        fallback_thresholds: thresholds (and their source) to use when the config has none.
        class_names: label code → name (defaults: the standard table).
        label_seconds: time already spent labeling, added to the timings.
    """
    cfg = config or TopologyConfig()
    free = grid.free
    P0 = np.asarray(histograms)
    if P0.ndim != 3 or P0.shape[:2] != grid.shape:
        raise ValueError(f"histograms must have shape {(*grid.shape, len(stats.classes))}, got {P0.shape}")
    names = dict(lbl.CLASS_NAMES)
    names.update(dict(class_names or {}))
    t0 = time.perf_counter()
    initial = argmax_labels(P0, stats, free)
    P = relax(P0, stats, free_mask=free, iterations=cfg.iterations, o=cfg.o, border=cfg.border)
    relaxed = argmax_labels(P, stats, free)
    t1 = time.perf_counter()
    merges: tuple[Merge, ...] = ()
    if cfg.correct:
        if cfg.thresholds is not None:
            th, source = cfg.thresholds, "config"
        elif fallback_thresholds is not None:
            th, source = fallback_thresholds
        else:
            th, source = CorrectionThresholds(), "book"
        corrected, merge_list = correct_regions(relaxed, grid.resolution, th, connectivity=cfg.connectivity)
        merges = tuple(merge_list)
        thresholds: CorrectionThresholds | None = th
    else:
        corrected, thresholds, source = relaxed.copy(), None, "none"
    t2 = time.perf_counter()
    graph = extract_regions(corrected, grid, connectivity=cfg.connectivity)
    t3 = time.perf_counter()
    segments = segments_from_regions(graph, free, codes=cfg.segment_codes, grow=cfg.grow_segments)
    t4 = time.perf_counter()
    timings = {
        "label": float(label_seconds),
        "relax": t1 - t0,
        "correct": t2 - t1,
        "regions": t3 - t2,
        "segments": t4 - t3,
    }
    timings["total"] = sum(timings.values())
    return TopologyResult(
        grid=grid,
        stats=stats,
        class_names=names,
        initial=initial,
        relaxed_proba=P,
        relaxed=relaxed,
        corrected=corrected,
        merges=merges,
        thresholds=thresholds,
        thresholds_source=source,
        graph=graph,
        segments=segments,
        timings=timings,
        config=cfg,
        map_labels=map_labels,
        meta=dict(meta or {}),
    )


def build_topology(
    grid: OccupancyGrid,
    model: PlaceModel,
    config: TopologyConfig | None = None,
    *,
    progress: ProgressFn | None = None,
    model_name: str = "the model",
) -> TopologyResult:
    """The whole chain for a map and a place model (see the module doc).

    Raises:
        ModelError: the model lacks relaxation statistics (the message says how to retrain).
    """
    stats = model_relaxation_stats(model, source=model_name)
    th = model_thresholds(model)
    t0 = time.perf_counter()
    ml = label_map(grid, model, progress=progress)
    P0 = histogram_image(ml, stats)
    label_seconds = time.perf_counter() - t0
    return topology_from_histograms(
        grid,
        P0,
        stats,
        config,
        fallback_thresholds=th,
        label_seconds=label_seconds,
        map_labels=ml,
        meta={"model_classes": list(model.classes), "free_cells": len(ml.cells)},
    )
