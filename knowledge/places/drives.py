"""Training scans the way the agent sees them: a simulated robot driving through a labelled map.

On the robot a front laser sees half a turn; the agent keeps a sparse local map of recent
beam endpoints and casts the rear half into it, interpolating beams that hit nothing
(Sect. 3.5, :func:`knowledge.metric.rear_beams.assemble_scan`). The 360° scan the classifier
gets therefore depends on where the robot came from: entering a room, the corridor it left
is behind it; in a straight corridor the far end behind the robot was never seen. Scans
cast over a full turn from map cells never show that. This module drives a simulated robot
through a labelled map and assembles every scan as the agent does:

* :func:`plan_tour` — a tour through random goals, on a lattice of points that keep
  ``clearance`` from every non-free cell, shortest paths preferring the middle of
  corridors and doors, smoothed;
* :func:`tour_poses` — poses along it every ``step`` metres, facing the way the robot
  drives, with turns on the spot at the goals;
* :func:`drive_scans` — front scans cast at those poses (optionally made real-looking by
  :func:`~knowledge.places.randomize.perturb_scans`), fed through a
  :class:`~knowledge.metric.local_map.LocalMap` and ``assemble_scan``; returns the 360°
  scans with the label of the cell each was taken in.

Metres and radians in the grid's world frame; a :class:`numpy.random.Generator` makes every
choice, so a seed gives the same scans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from knowledge.errors import MapError
from knowledge.metric.local_map import LocalMap, LocalMapParams
from knowledge.metric.raycast import cast
from knowledge.metric.rear_beams import FullScanParams, assemble_scan
from knowledge.places.dataset import LabelledMap
from knowledge.places.randomize import ScanNoiseParams, perturb_scans

__all__ = ["DriveParams", "DriveScans", "Sensor", "assemble_along", "drive_scans", "plan_tour", "tour_poses"]

#: Cost per metre on the lattice: ``1 + CENTRE_WEIGHT · max(0, prefer − clearance)²``.
CENTRE_WEIGHT = 6.0


@dataclass(frozen=True)
class DriveParams:
    """How the simulated robot drives.

    Attributes:
        clearance: metres kept from every non-free cell (the base's radius and a margin).
        prefer: metres of clearance up to which paths are pushed away from obstacles.
        lattice: metres between planning lattice points.
        step: (min, max) metres driven between two scans (a SICK at 4–5 Hz at 0.4 m/s: 0.1 m).
        turn: radians turned between two scans when turning on the spot.
        spin: probability of turning on the spot at a goal (by up to a half turn either way).
        smooth: metres; the lattice path is averaged over this length before it is driven.
    """

    clearance: float = 0.3
    prefer: float = 0.8
    lattice: float = 0.2
    step: tuple[float, float] = (0.05, 0.15)
    turn: float = math.radians(10.0)
    spin: float = 0.5
    smooth: float = 0.6

    def __post_init__(self) -> None:
        for name in ("clearance", "prefer", "lattice", "turn", "smooth"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"DriveParams.{name} must be a positive number, got {v!r}")
        lo, hi = self.step
        if not (0 < lo <= hi):
            raise ValueError(
                f"DriveParams.step must be (min, max) metres with 0 < min <= max, got {self.step!r}"
            )
        if not 0 <= self.spin <= 1:
            raise ValueError(f"DriveParams.spin is a probability, got {self.spin!r}")


@dataclass(frozen=True)
class Sensor:
    """The simulated laser: ``n_beams`` beams over ``fov`` radians centred on the heading
    (both ends included, as a SICK's −90° … +90°), ``max_range`` metres."""

    fov: float = math.pi
    n_beams: int = 361
    max_range: float = 30.0

    @property
    def angles(self) -> np.ndarray:
        """``(n_beams,)`` beam angles in the sensor frame, radians."""
        if self.fov >= 2 * math.pi - 1e-9:
            return np.arange(self.n_beams) * (2 * math.pi / self.n_beams)
        return -self.fov / 2 + np.arange(self.n_beams) * (self.fov / (self.n_beams - 1))


class _Lattice:
    """Planning lattice points of a grid and the weighted graph between 8-neighbours."""

    def __init__(self, lmap: LabelledMap, params: DriveParams) -> None:
        grid = lmap.grid
        res = grid.resolution
        clear = ndimage.distance_transform_edt(grid.free) * res
        k = max(1, round(params.lattice / res))
        sub = clear[::k, ::k]
        ok = sub >= params.clearance
        idx = -np.ones(sub.shape, dtype=np.int64)
        idx[ok] = np.arange(int(ok.sum()))
        rc = np.argwhere(ok)
        self.cells = rc * k
        self.xy = grid.cell_to_world(self.cells)
        penalty = 1.0 + CENTRE_WEIGHT * np.maximum(0.0, params.prefer - sub[ok]) ** 2
        src, dst, w = [], [], []
        H, W = sub.shape
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a = idx[: H - dr, max(0, -dc) : W - max(0, dc)]
            b = idx[dr:, max(0, dc) : W - max(0, -dc)]
            both = (a >= 0) & (b >= 0)
            ia, ib = a[both], b[both]
            length = math.hypot(dr, dc) * k * res
            src.append(ia)
            dst.append(ib)
            w.append(length * 0.5 * (penalty[ia] + penalty[ib]))
        n = len(rc)
        s, d, ww = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
        self.graph = csr_matrix(
            (np.concatenate((ww, ww)), (np.concatenate((s, d)), np.concatenate((d, s)))), shape=(n, n)
        )
        _, self.component = connected_components(self.graph, directed=False)

    def __len__(self) -> int:
        return int(self.xy.shape[0])


def plan_tour(
    lmap: LabelledMap, rng: np.random.Generator, goals: int, params: DriveParams | None = None
) -> np.ndarray:
    """``(k, 2)`` world points of a tour through ``goals`` random goals (lattice resolution).

    The tour starts at a random lattice point of the largest connected part of the free
    space and visits goals drawn uniformly over that part (so rooms, which hold most of the
    area, get most of the visits, and the corridors are driven on the way between them).

    Raises:
        MapError: no point of the map keeps the clearance.
    """
    prm = params or DriveParams()
    lat = _Lattice(lmap, prm)
    if len(lat) == 0:
        raise MapError(f"{lmap.name}: no free cell keeps {prm.clearance} m from obstacles; nothing to drive")
    main = np.bincount(lat.component).argmax()
    nodes = np.flatnonzero(lat.component == main)
    at = int(rng.choice(nodes))
    path = [at]
    for _ in range(goals):
        goal = int(rng.choice(nodes))
        _, pred = dijkstra(lat.graph, indices=at, return_predecessors=True)
        leg = [goal]
        while leg[-1] != at and pred[leg[-1]] >= 0:
            leg.append(int(pred[leg[-1]]))
        path.extend(reversed(leg[:-1]))
        at = goal
    return lat.xy[np.asarray(path)]


def _resample(points: np.ndarray, spacing: float) -> np.ndarray:
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    if s[-1] <= 0:
        return points[:1]
    t = np.arange(0.0, s[-1], spacing)
    return np.column_stack((np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])))


def tour_poses(path: np.ndarray, rng: np.random.Generator, params: DriveParams | None = None) -> np.ndarray:
    """``(N, 3)`` poses ``(x, y, θ)`` along a planned tour: smoothed, one every ``step``
    metres facing the direction of travel, and turns on the spot (one pose every ``turn``)
    where the direction changes sharply and, with probability ``spin``, at corners."""
    prm = params or DriveParams()
    if len(path) < 2:
        return np.column_stack((path[:1], np.zeros(min(1, len(path)))))
    fine = _resample(path, 0.05)
    w = max(1, round(prm.smooth / 0.05))
    if len(fine) > 2 * w:
        kernel = np.ones(w) / w
        sm = np.column_stack([np.convolve(fine[:, j], kernel, mode="valid") for j in range(2)])
        fine = np.vstack((fine[:1], sm, fine[-1:]))
    dense = _resample(fine, 0.01)
    seg = np.hypot(*np.diff(dense, axis=0).T)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    out: list[tuple[float, float, float]] = []
    pos = 0.0
    heading = None
    while pos < s[-1]:
        j = min(int(np.searchsorted(s, pos)), len(dense) - 2)
        x, y = dense[j]
        ahead = dense[min(j + 20, len(dense) - 1)] - dense[j]
        th = math.atan2(ahead[1], ahead[0]) if np.hypot(*ahead) > 1e-9 else (heading or 0.0)
        if heading is not None:
            turn = math.remainder(th - heading, 2 * math.pi)
            if abs(turn) > 2 * prm.turn:  # turn on the spot first
                if rng.random() < prm.spin:  # sometimes the long way round
                    turn -= math.copysign(2 * math.pi, turn) if rng.random() < 0.2 else 0.0
                k = int(abs(turn) // prm.turn)
                for i in range(1, k + 1):
                    out.append((x, y, heading + math.copysign(i * prm.turn, turn)))
        heading = th
        out.append((x, y, th))
        pos += rng.uniform(*prm.step)
    P = np.array(out)
    P[:, 2] = np.arctan2(np.sin(P[:, 2]), np.cos(P[:, 2]))
    return P


@dataclass(frozen=True, eq=False)
class DriveScans:
    """Scans assembled along a drive.

    Attributes:
        ranges: ``(N, n)`` float32 360° scans as the agent assembles them (beam i at i·2π/n).
        y: ``(N,)`` class names of the cells the scans were taken in.
        cells: ``(N, 2)`` (row, col) of those cells.
        coverage: ``(N,)`` share of each scan's beams measured or hit in the local map.
        poses: ``(N, 3)`` the sensor poses.
    """

    ranges: np.ndarray
    y: np.ndarray
    cells: np.ndarray
    coverage: np.ndarray
    poses: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))

    def __len__(self) -> int:
        return int(self.y.shape[0])


def drive_scans(
    lmap: LabelledMap,
    poses: np.ndarray,
    rng: np.random.Generator,
    *,
    sensor: Sensor | None = None,
    noise: ScanNoiseParams | None = None,
    out: FullScanParams | None = None,
    local_map: LocalMapParams | None = None,
    keep_every: int = 1,
    min_coverage: float = 0.0,
) -> DriveScans:
    """Drive ``poses`` through ``lmap`` and assemble the agent's 360° scan at each.

    Args:
        lmap: the labelled map (scans on unlabelled or non-free cells are not returned).
        poses: ``(N, 3)`` sensor poses in the grid's world frame, in driving order.
        rng: random generator for the scan noise.
        sensor: the simulated laser (default: a SICK LMS, 180°, 361 beams, 30 m).
        noise: scan perturbation (None: exact casts).
        out: the assembled scans' beams and range (the place model's: default 360, 30 m).
        local_map: the sparse local map's parameters (the agent's defaults).
        keep_every: return every k-th scan (all feed the local map).
        min_coverage: scans whose known share is below this are not returned.

    Stamps advance by 0.25 s per scan (the local map forgets by age).
    """
    sen = sensor or Sensor()
    prm = out or FullScanParams()
    P = np.asarray(poses, dtype=np.float64)
    angles = sen.angles
    front = cast(
        lmap.grid, P, n_beams=sen.n_beams, max_range=sen.max_range, fov=sen.fov, angle_min=float(angles[0])
    )
    if noise is not None:
        front = perturb_scans(front, angles, rng, max_range=sen.max_range, params=noise)
    cells = lmap.grid.world_to_cell(P[:, :2])
    inside = lmap.grid.in_bounds(cells)
    codes = np.zeros(len(P), dtype=np.int64)
    codes[inside] = lmap.labels[cells[inside, 0], cells[inside, 1]]
    want = (codes > 0) & (np.arange(len(P)) % keep_every == 0)
    ranges, cov = assemble_along(
        front, angles, P, range_max=sen.max_range, want=want, out=prm, local_map=local_map
    )
    good = cov >= min_coverage
    idx = np.flatnonzero(want)[good]
    rows, cov = ranges[good], cov[good]
    names = (
        np.array([lmap.names[int(c)] for c in codes[idx]], dtype=str) if len(idx) else np.array([], dtype=str)
    )
    return DriveScans(
        ranges=rows,
        y=names,
        cells=cells[idx],
        coverage=cov,
        poses=P[idx],
    )


def assemble_along(
    front: np.ndarray,
    angles: np.ndarray,
    poses: np.ndarray,
    *,
    range_max: float,
    want: np.ndarray | None = None,
    stamps: np.ndarray | None = None,
    out: FullScanParams | None = None,
    local_map: LocalMapParams | None = None,
    range_min: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The agent's 360° scans along a sequence of (front) scans, as the pipeline assembles them.

    Args:
        front: ``(N, B)`` metres, in time order; ``range_max`` or more is no echo.
        angles: ``(B,)`` beam angles in the sensor frame, radians.
        poses: ``(N, 3)`` sensor poses in one fixed frame.
        range_max: the sensor's maximum range.
        want: ``(N,)`` bool, the scans to assemble (all feed the local map); default all.
        stamps: ``(N,)`` seconds (default 0.25 s apart).
        out: the assembled scans' beams and range (default 360, 30 m).
        local_map: the local map's parameters (the agent's defaults).
        range_min: readings below it are invalid.

    Returns:
        ``(K, n)`` float32 scans and ``(K,)`` float32 coverage (share of beams known) of the
        ``K`` wanted scans.
    """
    prm = out or FullScanParams()
    F = np.asarray(front)
    N = F.shape[0]
    w = np.ones(N, dtype=bool) if want is None else np.asarray(want, dtype=bool)
    t = 0.25 * np.arange(N) if stamps is None else np.asarray(stamps, dtype=np.float64)
    lm = LocalMap(local_map or LocalMapParams())
    rows = np.empty((int(w.sum()), prm.n_beams), dtype=np.float32)
    cov = np.empty(int(w.sum()), dtype=np.float32)
    k = 0
    for i in range(N):
        lm.add(F[i], angles, poses[i], stamp=float(t[i]), range_max=range_max, range_min=range_min)
        if not w[i]:
            continue
        r, known = assemble_scan(
            F[i], angles, range_max=range_max, pose=poses[i], local_map=lm, params=prm, range_min=range_min
        )
        rows[k], cov[k] = r, float(known.mean())
        k += 1
    return rows, cov
