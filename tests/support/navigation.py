"""A robot driven along a polyline through a navigation graph, passing doorways."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from knowledge.navigation.doorways import Doorway
from knowledge.navigation.graph import NavigationGraph

Point = tuple[float, float]


def drive(
    g: NavigationGraph,
    points: Sequence[Point],
    *,
    label: str = "room",
    doors: Sequence[tuple[Point, float]] = (),
    step: float = 0.05,
) -> None:
    """Drive the polyline ``points``; a doorway ``(centre, normal)`` is reported (and the robot
    counts as in the opening within 0.2 m of it) where the path passes through it."""
    passed: set[int] = set()
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        n = max(1, int(math.hypot(x1 - x0, y1 - y0) / step))
        heading = math.atan2(y1 - y0, x1 - x0)
        for t in np.linspace(0.0, 1.0, n, endpoint=False):
            x, y = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
            doorway, in_opening = None, False
            for i, ((cx, cy), normal) in enumerate(doors):
                d = math.hypot(x - cx, y - cy)
                in_opening = in_opening or d < 0.2
                if d < 0.2 and i not in passed:
                    passed.add(i)
                    # the normal points the way the robot passes
                    along = math.cos(heading - normal) >= 0
                    doorway = Doorway((cx, cy), 0.9, normal if along else normal + math.pi, 0.0)
                elif d >= 0.4:
                    passed.discard(i)
            g.update((x, y, heading), label, doorway, in_opening=in_opening)
    g.update((*points[-1], 0.0), label)
