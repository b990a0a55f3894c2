"""Labelled maps and the training examples drawn from them.

A *labelled map* is an occupancy grid plus a label image of the same shape (class codes
of :mod:`knowledge.labels`). Training examples are simulated 360° scans from the centres
of labelled free cells, taken on a regular stride, as in the book's experiments (a
simulated robot placed in the free cells of the map, Sect. 3.6.1).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from knowledge import labels as lbl
from knowledge.errors import MapError
from knowledge.metric.grid import OccupancyGrid

#: The five labelled buildings of ../shared/data/ipa/labeled.
IPA_BUILDINGS = ("Fr52", "lab_d_furnitures", "lab_intel", "lab_ipa", "office_e")
#: No file of the IPA data stores a resolution; its README says 0.05 m per pixel.
IPA_RESOLUTION = 0.05

ProgressFn = Callable[[str, int, int], None]
"""``progress(stage, done, total)``: called as long work advances."""


@dataclass(frozen=True, eq=False)
class LabelledMap:
    """An occupancy grid with per-cell class codes.

    Attributes:
        grid: the occupancy grid.
        labels: ``(rows, cols)`` uint8 class codes (0 = unlabelled), same shape as the grid.
        names: code → class name for the codes that occur (the standard table plus a legend).
    """

    grid: OccupancyGrid
    labels: np.ndarray
    names: Mapping[int, str] = field(default_factory=lambda: dict(lbl.CLASS_NAMES))

    def __post_init__(self) -> None:
        lab = np.asarray(self.labels)
        if lab.shape != self.grid.shape:
            raise MapError(
                f"{self.grid.name}: label image {lab.shape} and map {self.grid.shape} differ in shape"
            )
        lab = np.ascontiguousarray(lab, dtype=np.uint8)
        lab.setflags(write=False)
        object.__setattr__(self, "labels", lab)
        unknown = sorted(set(np.unique(lab).tolist()) - {0} - set(self.names))
        if unknown:
            raise MapError(
                f"{self.grid.name}: label codes {unknown} have no class name; "
                "name them in a legend JSON beside the label image"
            )

    @property
    def name(self) -> str:
        return self.grid.name

    def labelled_free(self) -> np.ndarray:
        """``(rows, cols)`` bool: free cells that carry a label."""
        return self.grid.free & (self.labels > 0)

    def class_counts(self) -> dict[str, int]:
        """Labelled free cells per class name."""
        codes, counts = np.unique(self.labels[self.labelled_free()], return_counts=True)
        return {self.names[int(c)]: int(n) for c, n in zip(codes, counts, strict=True)}


def detect_codes(raw: np.ndarray) -> str:
    """``"ipa"`` if a raw label image uses the IPA grey values (77/115/179), else ``"standard"``."""
    values = set(np.unique(raw).tolist()) - {0}
    if values and values <= set(lbl.IPA_CODES) and not values <= set(range(1, 16)):
        return "ipa"
    return "standard"


def load_labelled_map(
    map_path: str | Path,
    labels_path: str | Path,
    *,
    resolution: float | None = None,
    codes: str = "auto",
    name: str | None = None,
) -> LabelledMap:
    """Load a map (YAML, or an image with ``resolution``) and its label image.

    ``codes``: ``"standard"`` (pixel values are the codes of :mod:`knowledge.labels`, a
    legend JSON may name more), ``"ipa"`` (77 room, 115 corridor, 179 doorway) or
    ``"auto"`` (detect from the values present).
    """
    grid = OccupancyGrid.load(map_path, resolution)
    if name:
        grid = OccupancyGrid(grid.state, grid.resolution, grid.origin, name)
    raw = lbl.read_label_image(labels_path)
    mode = detect_codes(raw) if codes == "auto" else codes
    if mode == "ipa":
        lab = lbl.read_label_image(labels_path, lbl.IPA_CODES)
        names: dict[int, str] = dict(lbl.CLASS_NAMES)
    elif mode == "standard":
        lab = raw
        names = lbl.read_legend(labels_path)
    else:
        raise ValueError(f"codes must be 'auto', 'standard' or 'ipa', got {codes!r}")
    lab = np.where(grid.free, lab, 0).astype(np.uint8)
    return LabelledMap(grid, lab, names)


def load_ipa_building(data_dir: str | Path, building: str) -> LabelledMap:
    """One of the labelled IPA buildings (``data_dir`` is ``../shared/data``)."""
    base = Path(data_dir) / "ipa" / "labeled"
    return load_labelled_map(
        base / f"{building}.map.png",
        base / f"{building}.labels.png",
        resolution=IPA_RESOLUTION,
        codes="ipa",
        name=building,
    )


def sample_cells(lmap: LabelledMap, stride: int, *, offset: int = 0) -> np.ndarray:
    """``(N, 2)`` (row, col) of labelled free cells on a regular grid of the given stride."""
    if stride < 1:
        raise ValueError(f"stride must be >= 1 cell, got {stride}")
    mask = lmap.labelled_free()
    sub = np.zeros_like(mask)
    sub[offset % stride :: stride, offset % stride :: stride] = True
    return np.argwhere(mask & sub)


@dataclass(frozen=True, eq=False)
class ScanSet:
    """Simulated scans with their labels.

    Attributes:
        ranges: ``(N, n_beams)`` float32 metres.
        y: ``(N,)`` class names (``<U`` array).
        source: ``(N,)`` index into ``maps`` of the map each scan came from.
        cells: ``(N, 2)`` (row, col) of each scan in its map.
        maps: names of the maps.
        kind: ``(N,)`` how each scan was made (e.g. "grid", "drive", "real"), or None.
    """

    ranges: np.ndarray
    y: np.ndarray
    source: np.ndarray
    cells: np.ndarray
    maps: tuple[str, ...]
    kind: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.y.shape[0])

    @property
    def kinds(self) -> np.ndarray:
        """``(N,)`` how each scan was made ("" where unknown)."""
        return self.kind if self.kind is not None else np.full(len(self), "", dtype="<U16")

    def subset(self, index: np.ndarray) -> ScanSet:
        """The scans selected by ``index`` (a boolean mask or integer indices)."""
        return ScanSet(
            self.ranges[index],
            self.y[index],
            self.source[index],
            self.cells[index],
            self.maps,
            None if self.kind is None else self.kind[index],
        )

    @staticmethod
    def concatenate(parts: Sequence[ScanSet]) -> ScanSet:
        """One set of all ``parts``' scans (their maps listed once each, in order)."""
        if not parts:
            raise ValueError("nothing to concatenate")
        maps: list[str] = []
        sources = []
        for p in parts:
            lut = []
            for name in p.maps:
                if name not in maps:
                    maps.append(name)
                lut.append(maps.index(name))
            sources.append(np.asarray(lut, dtype=np.int32)[p.source] if len(p) else p.source.astype(np.int32))
        kinds = [p.kinds for p in parts]
        return ScanSet(
            np.concatenate([p.ranges for p in parts]),
            np.concatenate([p.y for p in parts]),
            np.concatenate(sources),
            np.concatenate([p.cells for p in parts]),
            tuple(maps),
            np.concatenate(kinds).astype("<U16"),
        )

    def class_counts(self) -> dict[str, int]:
        names, counts = np.unique(self.y, return_counts=True)
        return {str(n): int(c) for n, c in zip(names, counts, strict=True)}


def simulate_scans(
    maps: Sequence[LabelledMap],
    *,
    stride: int,
    n_beams: int,
    max_range: float,
    classes: Iterable[str] | None = None,
    progress: ProgressFn | None = None,
) -> ScanSet:
    """Cast a 360° scan from every ``stride``-th labelled free cell of each map.

    Cells whose class is not in ``classes`` (when given) are skipped.
    """
    from knowledge.metric.raycast import cast_cells

    keep = set(classes) if classes is not None else None
    all_ranges, all_y, all_src, all_cells = [], [], [], []
    for i, lmap in enumerate(maps):
        cells = sample_cells(lmap, stride)
        names = np.array([lmap.names[int(c)] for c in lmap.labels[cells[:, 0], cells[:, 1]]])
        if keep is not None:
            sel = np.isin(names, sorted(keep))
            cells, names = cells[sel], names[sel]
        if len(cells) == 0:
            continue

        def cb(done: int, total: int, _name: str = lmap.name) -> None:
            if progress is not None:
                progress(f"casting {_name}", done, total)

        ranges = cast_cells(lmap.grid, cells, n_beams=n_beams, max_range=max_range, progress=cb)
        all_ranges.append(ranges)
        all_y.append(names)
        all_src.append(np.full(len(cells), i, dtype=np.int32))
        all_cells.append(cells)
    if not all_ranges:
        raise MapError("no labelled free cells to train on (check the label images, stride and classes)")
    return ScanSet(
        ranges=np.concatenate(all_ranges),
        y=np.concatenate(all_y),
        source=np.concatenate(all_src),
        cells=np.concatenate(all_cells),
        maps=tuple(m.name for m in maps),
    )
