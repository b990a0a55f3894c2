"""Whole-map labeling: a simulated 360° scan from every free cell, classified by a place model.

This is Sect. 4.5's first step (and the book's test protocol): for each free cell of an
occupancy grid, cast the scan the robot would see there, compute the features the model
uses, and run the probabilistic decision list. The result is a class histogram per free
cell and the label image of the most probable classes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from knowledge import labels as lbl
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast_cells
from knowledge.places.model import PlaceModel

ProgressFn = Callable[[str, int, int], None]
"""``progress(stage, done, total)``."""

#: Scans classified per batch: bounds the memory of the feature matrix.
DEFAULT_CHUNK = 32_768


def class_codes(classes: tuple[str, ...]) -> dict[str, int]:
    """Label-image code of each class: the standard code where there is one, else 5, 6, ..."""
    codes: dict[str, int] = {}
    spare = iter(range(5, 256))
    for c in classes:
        codes[c] = lbl.CLASS_CODES[c] if c in lbl.CLASS_CODES else next(spare)
    return codes


@dataclass(frozen=True, eq=False)
class MapLabels:
    """The labeling of every free cell of a map.

    Attributes:
        labels: ``(rows, cols)`` uint8 codes (0 on non-free cells).
        cells: ``(N, 2)`` (row, col) of the classified cells, row-major.
        proba: ``(N, K)`` float32 class histograms (eq. 4.5), columns in ``classes`` order.
        classes: the model's class names.
        codes: class name → label code used in ``labels``.
        timings: seconds per stage (``cast``, ``classify``, ``total``).
    """

    labels: np.ndarray
    cells: np.ndarray
    proba: np.ndarray
    classes: tuple[str, ...]
    codes: Mapping[str, int]
    timings: Mapping[str, float] = field(default_factory=dict)

    @property
    def legend(self) -> dict[int, str]:
        """Code → class name, for :func:`knowledge.labels.write_label_image`."""
        return {code: name for name, code in self.codes.items()}

    def predicted(self) -> np.ndarray:
        """``(N,)`` class names of the classified cells."""
        return np.asarray(self.classes)[np.argmax(self.proba, axis=1)]

    def proba_image(self) -> np.ndarray:
        """``(rows, cols, K)`` float32 histograms, zeros on non-free cells."""
        out = np.zeros((*self.labels.shape, len(self.classes)), dtype=np.float32)
        out[self.cells[:, 0], self.cells[:, 1]] = self.proba
        return out


def label_map(
    grid: OccupancyGrid,
    model: PlaceModel,
    *,
    cells: np.ndarray | None = None,
    chunk: int = DEFAULT_CHUNK,
    progress: ProgressFn | None = None,
) -> MapLabels:
    """Classify every free cell of ``grid`` (or the given ``(N, 2)`` cells) with ``model``."""
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1 scan, got {chunk}")
    t0 = time.perf_counter()
    todo = grid.free_cells() if cells is None else np.asarray(cells, dtype=np.int64)
    scan = model.scan

    def cast_progress(done: int, total: int) -> None:
        if progress is not None:
            progress("cast", done, total)

    ranges = cast_cells(grid, todo, n_beams=scan.n_beams, max_range=scan.max_range, progress=cast_progress)
    t1 = time.perf_counter()
    n = len(todo)
    proba = np.empty((n, len(model.classes)), dtype=np.float32)
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        proba[start:stop] = model.predict_proba_scans(ranges[start:stop])
        if progress is not None:
            progress("classify", stop, n)
    del ranges
    t2 = time.perf_counter()
    codes = class_codes(model.classes)
    code_of = np.array([codes[c] for c in model.classes], dtype=np.uint8)
    labels = np.zeros(grid.shape, dtype=np.uint8)
    if n:
        labels[todo[:, 0], todo[:, 1]] = code_of[np.argmax(proba, axis=1)]
    return MapLabels(
        labels=labels,
        cells=todo,
        proba=proba,
        classes=model.classes,
        codes=codes,
        timings={"cast": t1 - t0, "classify": t2 - t1, "total": time.perf_counter() - t0},
    )
