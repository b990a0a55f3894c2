"""Nearest seeds along free cells: the octile distance in open space, walls that keep cells
from seeds behind them, and cells no seed reaches."""

from __future__ import annotations

import math

import numpy as np

from knowledge.metric.geodesic import nearest_seeds


def test_in_open_space_the_nearest_seed_is_the_nearest_by_octile_distance(rng: np.random.Generator) -> None:
    free = np.ones((40, 55), dtype=bool)
    seeds = rng.integers(0, (40, 55), size=(12, 2))
    got = nearest_seeds(free, seeds)
    rr, cc = np.mgrid[:40, :55]
    d = np.stack(
        [
            np.maximum(abs(rr - r), abs(cc - c)) + (math.sqrt(2) - 1) * np.minimum(abs(rr - r), abs(cc - c))
            for r, c in seeds
        ]
    )
    best = d.min(axis=0)
    unique = (np.abs(d - best) < 1e-9).sum(axis=0) == 1  # cells without a tie
    assert unique.mean() > 0.8
    assert (d[got, rr, cc] == best)[~unique].all()  # a tie goes to one of the nearest
    assert (got[unique] == d.argmin(axis=0)[unique]).all()


def test_a_wall_keeps_cells_from_the_seed_behind_it_and_cut_off_cells_get_none() -> None:
    free = np.ones((10, 21), dtype=bool)
    free[:, 10] = False  # a wall down the middle ...
    free[9, 10] = True  # ... with a gap at the bottom
    free[0:3, 0:3] = False
    free[1, 1] = True  # a free cell walled in
    # seed 0 left of the wall, close to it; seed 1 far right; seed 2 outside the grid
    got = nearest_seeds(free, np.array([[0, 8], [0, 20], [50, 50]]))
    # right of the wall, away from the gap: seed 1's, though seed 0 is nearer in a straight line
    assert (got[:6, 11:] == 1).all()
    assert got[9, 11] == 0  # beside the gap, seed 0 is nearer through it
    assert (got[:8, 3:10] == 0).all()
    assert got[1, 1] == -1 and (got[~free] == -1).all()
    # a seed on a cell that is not free still starts a walk; of two seeds on one cell the first counts
    wall = nearest_seeds(free, np.array([[4, 10], [4, 10]]))
    assert (wall[free & (np.arange(21) != 1)[None, :]] >= 0).sum() > 150 and set(np.unique(wall)) == {-1, 0}
