"""Legs → people: pair the detected leg segments of one scan into persons.

Pairs are chosen greedily by increasing distance between leg centroids: the closest two
unpaired legs are paired if they are at most ``max_distance`` apart (0.6 m by default: a
walking person's legs at knee height are rarely further apart), then the next closest, and so
on. A person's position is the midpoint of its legs.

A *lone* leg (no partner within ``max_distance``) is common and usually still a person: one
leg hides the other from the laser, or both legs are closer than the 15 cm jump distance and
form a single segment. With ``lone_legs="person"`` (default) it becomes a person at the leg's
centroid with one leg; with ``"drop"`` it is discarded (fewer false alarms from leg-like
furniture, more missed people). The tracker then decides, over several scans, what is real.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from knowledge.people.segmentation import FloatArray

#: Largest distance between the two legs of one person, metres.
DEFAULT_MAX_DISTANCE = 0.6
LONE_LEG_POLICIES = ("person", "drop")


@dataclass(frozen=True, eq=False)
class People:
    """The persons of one scan.

    Attributes:
        positions: ``(P, 2)`` float64 metres, in the frame of the legs given.
        legs: ``(P, 2)`` intp indices of each person's legs in the input; ``legs[p, 1] = −1``
            for a person seen with one leg.
    """

    positions: FloatArray
    legs: npt.NDArray[np.intp]

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_legs(self) -> npt.NDArray[np.intp]:
        """``(P,)`` 1 or 2."""
        return np.asarray(1 + (self.legs[:, 1] >= 0), dtype=np.intp)


def pair_legs(
    legs: npt.ArrayLike,
    *,
    max_distance: float = DEFAULT_MAX_DISTANCE,
    lone_legs: str = "person",
) -> People:
    """Pair leg centroids ``(K, 2)`` (metres) into people (see the module doc)."""
    L = np.asarray(legs, dtype=np.float64).reshape(-1, 2) if np.size(legs) else np.zeros((0, 2))
    if not (math.isfinite(max_distance) and max_distance > 0):
        raise ValueError(f"max_distance must be a positive number of metres, got {max_distance!r}")
    if lone_legs not in LONE_LEG_POLICIES:
        raise ValueError(f"lone_legs must be one of {LONE_LEG_POLICIES}, got {lone_legs!r}")
    K = L.shape[0]
    rows: list[tuple[int, int]] = []
    used = [False] * K
    if K >= 2:
        i, j = _upper_pairs(K)
        d = np.hypot(L[i, 0] - L[j, 0], L[i, 1] - L[j, 1])
        close = np.flatnonzero(d <= max_distance)
        if close.size:
            order = close[np.argsort(d[close], kind="stable")]
            for a, b in zip(i[order].tolist(), j[order].tolist(), strict=True):
                if not (used[a] or used[b]):
                    used[a] = used[b] = True
                    rows.append((a, b))
    if lone_legs == "person":
        rows += [(a, -1) for a in range(K) if not used[a]]
    if not rows:
        return People(np.zeros((0, 2)), np.zeros((0, 2), dtype=np.intp))
    idx = np.array(rows, dtype=np.intp)
    second = np.where(idx[:, 1] >= 0, idx[:, 1], idx[:, 0])
    positions = 0.5 * (L[idx[:, 0]] + L[second])
    return People(positions, idx)


@functools.lru_cache(maxsize=64)
def _upper_pairs(k: int) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """``(i, j)`` of all pairs ``i < j < k`` in row-major order (:func:`numpy.triu_indices`), read-only."""
    i, j = np.triu_indices(k, k=1)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j
