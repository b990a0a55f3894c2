"""A small drawn office with place labels, for the whole-map labeling tests (iAMN)."""

from __future__ import annotations

import itertools

import numpy as np

from knowledge import labels as lbl
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.dataset import LabelledMap


def drawn_office() -> LabelledMap:
    """0.1 m cells, 9 m × 26 m: a 1.4 m corridor along the middle, rooms of different widths
    above and below, each with a 1 m door (the door cells and 0.3 m either side are doorway)."""
    rows, cols = 90, 260
    occ = np.zeros((rows, cols), bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    top, bottom = (37, 39), (52, 54)  # wall rows between rooms and corridor
    occ[top[0] : top[1], :] = True
    occ[bottom[0] : bottom[1], :] = True
    lab = np.zeros((rows, cols), np.uint8)
    lab[1 : top[0], :] = lbl.ROOM
    lab[bottom[1] : -1, :] = lbl.ROOM
    lab[top[1] : bottom[0], :] = lbl.CORRIDOR
    # room walls (columns) above and below the corridor, and a door in the middle of each room
    for walls, (r0, r1), (w0, w1) in (
        ((40, 95, 130, 190), top, (1, top[0])),
        ((55, 100, 160, 215), bottom, (bottom[1], rows - 1)),
    ):
        for c in walls:
            occ[w0:w1, c : c + 2] = True
        for a, b in itertools.pairwise((0, *walls, cols - 1)):
            door = (a + b) // 2
            occ[r0:r1, door - 5 : door + 5] = False
            lab[r0 - 3 : r1 + 3, door - 5 : door + 5] = lbl.DOORWAY
    grid = OccupancyGrid.from_masks(occ, 0.1, name="drawn-office")
    return LabelledMap(grid, np.where(grid.free, lab, 0).astype(np.uint8))
