"""Nearest seeds along free space: which of a set of seed cells each free cell of a grid is
nearest to, walking through free cells only (so a wall keeps a room's cells from a seed in
the corridor behind it, however close it lies in a straight line).

The walk goes between 8-neighbours, a step costing 1 cell side straight and √2 diagonally
(Dijkstra's shortest paths from all seeds at once, :func:`scipy.sparse.csgraph.dijkstra`).
Cells are ``(row, col)`` of an :class:`~knowledge.metric.grid.OccupancyGrid`'s arrays.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

__all__ = ["nearest_seeds"]

#: The 8-neighbourhood, one direction of each pair: (row step, column step).
_STEPS = ((0, 1), (1, 0), (1, 1), (1, -1))


def nearest_seeds(free: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """For each cell, the index of the seed nearest to it along free cells.

    Args:
        free: ``(rows, cols)`` bool, the cells one may walk through.
        seeds: ``(N, 2)`` int ``(row, col)`` of the seeds. A seed on a cell that is not free
            still starts a walk (a graph node on a cell its own scans marked occupied);
            seeds outside the grid are left out; of seeds on one cell the first counts.

    Returns:
        ``(rows, cols)`` int64: an index into ``seeds``, ``-1`` for cells that are not free
        or that no seed reaches.
    """
    walk = np.asarray(free, dtype=bool)
    if walk.ndim != 2:
        raise ValueError(f"free must be a 2-D mask, got shape {walk.shape}")
    rc = np.asarray(seeds, dtype=np.int64).reshape(-1, 2)
    rows, cols = walk.shape
    out = np.full((rows, cols), -1, dtype=np.int64)
    inside = np.flatnonzero((rc[:, 0] >= 0) & (rc[:, 0] < rows) & (rc[:, 1] >= 0) & (rc[:, 1] < cols))
    if inside.size == 0:
        return out
    flat = rc[inside, 0] * cols + rc[inside, 1]
    flat, first = np.unique(flat, return_index=True)  # of seeds on one cell, the first
    owner = inside[first]
    walk = walk.copy()
    walk.flat[flat] = True
    idx = np.full((rows, cols), -1, dtype=np.int64)
    idx[walk] = np.arange(int(walk.sum()))
    src, dst, cost = [], [], []
    for dr, dc in _STEPS:
        a = idx[: rows - dr, max(0, -dc) : cols - max(0, dc)]
        b = idx[dr:, max(0, dc) : cols - max(0, -dc)]
        both = (a >= 0) & (b >= 0)
        src.append(a[both])
        dst.append(b[both])
        cost.append(np.full(int(both.sum()), math.hypot(dr, dc)))
    n = int(walk.sum())
    s, d, w = np.concatenate(src), np.concatenate(dst), np.concatenate(cost)
    graph = csr_matrix((w, (s, d)), shape=(n, n))
    _, _, source = dijkstra(
        graph, directed=False, indices=idx.flat[flat], return_predecessors=True, min_only=True
    )
    # source: the graph index of the nearest seed's cell (-9999 where none reaches)
    seed_of = np.full(n, -1, dtype=np.int64)
    seed_of[idx.flat[flat]] = owner
    reached = source >= 0
    nearest = np.full(n, -1, dtype=np.int64)
    nearest[reached] = seed_of[source[reached]]
    out[walk] = nearest
    out[~np.asarray(free, dtype=bool)] = -1
    return out
