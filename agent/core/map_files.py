"""The occupancy map a run builds, saved as files other tools load: map_server YAML + PGM
and the place-label image with its YAML.

Both ``loci replay --out-dir`` and the running agent (``loci/<r>/map/save``, ``loci map
save``) build the map the same way: every processed scan is integrated into a
:class:`~knowledge.metric.mapping.ScanMapper` at the laser pose the pipeline gave it
(:func:`add_step`), so the map lies in the navigation graph's frame (``map`` with
``[localization]`` tracking, else ``odom``) and a replay of a recording saves the map its
live run saved.

:func:`save_map` writes into a folder:

* ``map.yaml`` + ``map.pgm``: the occupancy grid as ``map_saver`` writes it (254 free,
  0 occupied, 205 unknown; ``origin`` the lower-left corner), which ``loci localize`` and
  nav2's ``map_server`` load;
* ``labels.png`` + ``labels.yaml`` (``mode: raw``, :mod:`knowledge.label_maps`): the place
  label of each free cell, codes as in :mod:`knowledge.labels`, and ``labels.legend.json``
  when a class has no standard code. The pipeline labels the navigation graph's nodes (a
  majority vote over the scans near each), not cells, so each free cell takes the label of
  the node nearest to it *along free cells* (:func:`~knowledge.metric.geodesic.nearest_seeds`:
  a wall keeps a room from the corridor node behind it). Cells no node reaches through free
  space, and cells nearest to a node without a label yet, stay 0 (no label). A room seen only
  through its door, never entered, takes the label of the node it is nearest to through the
  door: the robot never classified it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from knowledge.errors import MapError
from knowledge.label_maps import write_label_map
from knowledge.labels import CLASS_NAMES, legend_path
from knowledge.metric.geodesic import nearest_seeds
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.mapping import ScanMapper
from knowledge.places.labeling import class_codes

if TYPE_CHECKING:
    from agent.core.pipeline import StepResult

__all__ = ["MAP_FILES", "add_step", "graph_labels", "save_map"]

#: The files :func:`save_map` writes (``labels.legend.json`` besides, when it is needed).
MAP_FILES = ("map.yaml", "map.pgm", "labels.png", "labels.yaml")


def add_step(mapper: ScanMapper, result: StepResult) -> None:
    """Integrate a processed scan at the laser pose the pipeline gave it."""
    scan, pose = result.scan, result.pose
    mapper.add(
        scan.ranges,
        scan.angles,
        (pose.x, pose.y, pose.theta),
        range_max=scan.range_max,
        range_min=scan.range_min,
    )


def graph_labels(grid: OccupancyGrid, graph: Mapping[str, Any]) -> tuple[np.ndarray, dict[int, str]]:
    """The label image of ``grid`` from a ``loci.graph/1`` message in the grid's frame.

    Returns:
        ``(rows, cols)`` uint8 codes (each free cell: the label of the node nearest along
        free cells; 0 elsewhere, see the module docstring) and code → class name of the
        classes used.
    """
    nodes = list(graph["nodes"])
    codes = class_codes(tuple(sorted({str(n["label"]) for n in nodes if n["label"]})))
    value = np.array([codes[n["label"]] if n["label"] else 0 for n in nodes] + [0], dtype=np.uint8)
    xy = np.array([[n["x"], n["y"]] for n in nodes], dtype=np.float64).reshape(-1, 2)
    nearest = nearest_seeds(grid.free, grid.world_to_cell(xy))
    return value[nearest], {code: name for name, code in codes.items()}  # index -1: the 0 at the end


def save_map(
    folder: str | Path, grid: OccupancyGrid, graph: Mapping[str, Any], *, overwrite: bool = True
) -> list[Path]:
    """Write ``grid`` and its label image (from ``graph``, see :func:`graph_labels`) into
    ``folder`` (made if missing): :data:`MAP_FILES`, each atomically. Returns the paths written.

    Raises:
        MapError: ``folder`` is a file, or (``overwrite`` off) already holds a saved map; nothing
            is written then.
        OSError: the folder cannot be made or written (permissions, a full disk).
    """
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise MapError(f"{out} is a file, not a folder: give a folder to save the map in")
    if not overwrite:
        there = [n for n in (*MAP_FILES, legend_path("labels.png").name) if (out / n).exists()]
        if there:
            raise MapError(
                f"{out} already holds a saved map ({', '.join(there)}): give another folder, or overwrite it"
            )
    labels, legend = graph_labels(grid, graph)
    out.mkdir(parents=True, exist_ok=True)
    image = out / "labels.png"
    written = [grid.save(out / "map.yaml"), out / "map.pgm", image]
    written.append(write_label_map(image, labels, grid.resolution, grid.origin, legend))
    stale = legend_path(image)
    if any(CLASS_NAMES.get(code) != name for code, name in legend.items()):
        written.append(stale)
    elif stale.exists():  # an earlier map's legend: these labels have none
        stale.unlink()
    return written
