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
#: Cells cast per block (≈ 377 MB of float32 ranges at 360 beams).
DEFAULT_BLOCK = 1 << 18


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


def label_map(
    grid: OccupancyGrid,
    model: PlaceModel,
    *,
    cells: np.ndarray | None = None,
    chunk: int = DEFAULT_CHUNK,
    block: int = DEFAULT_BLOCK,
    progress: ProgressFn | None = None,
) -> MapLabels:
    """Classify every free cell of ``grid`` (or the given ``(N, 2)`` cells) with ``model``.

    Cells are cast in blocks of ``block`` (each cast also pays a whole-grid set-up, so
    blocks are large) into one reused buffer, and classified ``chunk`` scans at a time:
    peak memory is about ``block × n_beams × 4`` bytes, not that of every scan of the map.
    """
    if chunk < 1 or block < 1:
        raise ValueError(f"chunk and block must be >= 1 scan, got {chunk} and {block}")
    t0 = time.perf_counter()
    todo = grid.free_cells() if cells is None else np.asarray(cells, dtype=np.int64)
    scan = model.scan
    n = len(todo)
    proba = np.empty((n, len(model.classes)), dtype=np.float32)
    buffer = np.empty((min(block, max(n, 1)), scan.n_beams), dtype=np.float32)
    t_cast = 0.0
    for b0 in range(0, n, block):
        b1 = min(n, b0 + block)
        out = buffer[: b1 - b0]
        tc = time.perf_counter()
        cast_cells(grid, todo[b0:b1], n_beams=scan.n_beams, max_range=scan.max_range, out=out)
        t_cast += time.perf_counter() - tc
        for start in range(b0, b1, chunk):
            stop = min(b1, start + chunk)
            proba[start:stop] = model.predict_proba_scans(out[start - b0 : stop - b0])
            if progress is not None:
                progress("label", stop, n)
    del buffer
    total = time.perf_counter() - t0
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
        timings={"cast": t_cast, "classify": total - t_cast, "total": time.perf_counter() - t0},
    )
