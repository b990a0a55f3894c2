"""Loop candidates and their verification: has the robot come back to a place it mapped?

A **candidate** for the newest keyframe ``k`` is an earlier keyframe ``j`` that lies within
a search radius of ``k``'s current estimate and far from it along the path
(:func:`propose`). The radius grows with the path driven between them, the drift the
estimates may have gathered since: ``r = radius + drift_rate · (s_k − s_j)`` metres, at most
``max_radius`` (``s``: metres along the path); the heading window likewise,
``angular_window + angular_drift_rate · (s_k − s_j)`` radians, at most ``max_angular_window``.

A candidate is **verified** by scan matching (:func:`verify`): the endpoints of ``j``'s
neighbouring keyframes (within ``local_map_travel`` metres of path either side of ``j``, none
of them within ``min_travel`` of ``k``) are laid at their current estimates into a local map
of occupied cells, whose likelihood field
(:class:`~knowledge.localization.likelihood.LikelihoodField`) ``k``'s scan is matched
against with the project's matcher (:class:`~knowledge.localization.scan_matching.ScanMatcher`):
a correlative search over the whole window (no prior: the window *is* the prior) on a
0.1 m copy of the map, then Gauss–Newton refinement on the 0.05 m map. The match is taken
only when every test of :class:`LoopParams` passes, and each check says which failed:

* ``points``: the scan has at least ``min_points`` endpoints;
* ``fit``: their mean score ``exp(−d²/2σ²)`` (σ 0.05 m) is at least ``min_fit``;
* ``inliers``: at least ``min_inliers`` of them end within ``inlier_distance`` of a mapped
  obstacle (a scan that sees much the local map does not know is not at that place);
* ``window``: the refined pose stays within the search window of the prior (the estimate
  of ``k``): the match agrees with what the robot believes, up to the drift allowed;
* ``constrained``: the translational part of the match's Gauss–Newton ``JᵀJ`` has a
  smallest eigenvalue of at least ``min_constraint`` of its largest — a corridor's walls
  alone leave the position along it free, and a loop there could be off by metres.

Poses are the laser's ``(x, y, theta)``, metres and radians; scan points ``(M, 2)`` metres in
the laser's frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.localization.likelihood import LikelihoodField, distance_field
from knowledge.localization.scan_matching import MatchField, MatchParams, ScanMatcher
from knowledge.localization.se2 import between, transform_points

__all__ = ["LoopCheck", "LoopParams", "local_field", "propose", "verify"]

#: Metres per cell of the local map (fine) and of its copy the correlative search runs on.
FINE, COARSE = 0.05, 0.1
#: Metres: distances in the local map's likelihood field are clipped here.
MAX_DISTANCE = 1.0


@dataclass(frozen=True)
class LoopParams:
    """How loops are proposed and verified (the module docstring says how each is used).

    Attributes:
        min_travel: metres along the path between a keyframe and a candidate.
        radius: metres, the search radius without drift.
        drift_rate: metres of radius per metre of path between the two.
        max_radius: metres, the largest radius (and linear search window).
        angular_window: radians, the heading window without drift.
        angular_drift_rate: radians per metre of path.
        max_angular_window: radians.
        max_candidates: candidates verified per keyframe (the nearest first).
        candidate_spacing: metres of path between two candidates of one keyframe.
        local_map_travel: metres of path either side of the candidate whose keyframes make
            the local map.
        min_points: endpoints the scan must have.
        min_fit: mean score of the endpoints at the match (σ 0.05 m).
        min_inliers: share of endpoints within ``inlier_distance`` of a mapped obstacle.
        inlier_distance: metres.
        min_constraint: smallest over largest eigenvalue of the match's translational ``JᵀJ``.
    """

    min_travel: float = 10.0
    radius: float = 0.5
    drift_rate: float = 0.003
    max_radius: float = 1.0
    angular_window: float = 0.1
    angular_drift_rate: float = 0.001
    max_angular_window: float = 0.25
    max_candidates: int = 2
    candidate_spacing: float = 3.0
    local_map_travel: float = 4.0
    min_points: int = 60
    min_fit: float = 0.75
    min_inliers: float = 0.85
    inlier_distance: float = 0.1
    min_constraint: float = 0.05

    def __post_init__(self) -> None:
        for name in (
            "min_travel",
            "radius",
            "max_radius",
            "angular_window",
            "max_angular_window",
            "local_map_travel",
            "inlier_distance",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"LoopParams.{name} must be a positive number, got {v!r}")
        for name in ("drift_rate", "angular_drift_rate", "candidate_spacing"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"LoopParams.{name} must be a number >= 0, got {v!r}")
        for name in ("min_fit", "min_inliers", "min_constraint"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"LoopParams.{name} must be in [0, 1], got {v!r}")
        if self.max_candidates < 1 or self.min_points < 1:
            raise ValueError("LoopParams.max_candidates and min_points must be >= 1")

    def windows(self, travel: float) -> tuple[float, float]:
        """``(metres, radians)``: the search radius and heading window after ``travel`` metres of path."""
        return (
            min(self.max_radius, self.radius + self.drift_rate * travel),
            min(self.max_angular_window, self.angular_window + self.angular_drift_rate * travel),
        )


@dataclass(frozen=True)
class LoopCheck:
    """One verified candidate: keyframe ``current`` matched near keyframe ``candidate``.

    Attributes:
        current, candidate: keyframe indices.
        travel: metres of path between them.
        distance: metres between their estimates when proposed.
        window: ``(metres, radians)`` the search window.
        accepted: every test passed.
        reason: ``"accepted"``, or the first test that failed with its numbers.
        fit: mean score of the endpoints at the match.
        inliers: share of endpoints within the inlier distance of an obstacle.
        constraint: smallest over largest eigenvalue of the translational ``JᵀJ``.
        shift: ``(metres, radians)`` from the prior to the match.
        pose: ``(3,)`` the current keyframe's matched pose (the graph's frame), None if not matched.
        relative: ``(3,)`` the candidate's pose to the matched pose (the loop edge), None if not matched.
    """

    current: int
    candidate: int
    travel: float
    distance: float
    window: tuple[float, float]
    accepted: bool
    reason: str
    fit: float = 0.0
    inliers: float = 0.0
    constraint: float = 0.0
    shift: tuple[float, float] = (0.0, 0.0)
    pose: np.ndarray | None = None
    relative: np.ndarray | None = None


def propose(
    k: int, estimates: np.ndarray, travel: np.ndarray, params: LoopParams
) -> list[tuple[int, float, float]]:
    """Candidates for keyframe ``k``: ``(j, distance, travel between)`` of the earlier
    keyframes within their radius of ``k``'s estimate and at least ``min_travel`` of path
    back, nearest (relative to the radius) first, ``candidate_spacing`` apart along the path,
    at most ``max_candidates``. ``estimates``: ``(K, 3)``; ``travel``: ``(K,)`` metres along
    the path at each keyframe."""
    back = travel[k] - travel[:k]
    older = np.nonzero(back >= params.min_travel)[0]
    if older.size == 0:
        return []
    dist = np.hypot(*(estimates[older, :2] - estimates[k, :2]).T)
    radius = np.minimum(params.max_radius, params.radius + params.drift_rate * back[older])
    near = dist <= radius
    order = np.argsort(dist[near] / radius[near], kind="stable")
    chosen: list[tuple[int, float, float]] = []
    for i in order:
        j = int(older[near][i])
        if all(abs(travel[j] - travel[c]) >= params.candidate_spacing for c, _, _ in chosen):
            chosen.append((j, float(dist[near][i]), float(back[j])))
            if len(chosen) >= params.max_candidates:
                break
    return chosen


def local_field(world_points: np.ndarray, pad: float) -> tuple[LikelihoodField, LikelihoodField]:
    """The likelihood fields of the occupied cells of ``(N, 2)`` world points, at
    :data:`FINE` and :data:`COARSE` metres per cell, sharing one origin (so that a pose in
    one's map frame is the same pose in the other's), with ``pad`` metres of room around."""
    lo = world_points.min(axis=0) - pad
    hi = world_points.max(axis=0) + pad
    ratio = round(COARSE / FINE)
    shape = np.ceil((hi - lo) / COARSE).astype(int) * ratio  # fine cells, a multiple of the ratio
    ij = np.floor((world_points - lo) / FINE).astype(int)
    occ = np.zeros((int(shape[1]), int(shape[0])), dtype=bool)  # rows = y
    occ[ij[:, 1], ij[:, 0]] = True
    coarse: np.ndarray = np.asarray(
        occ.reshape(occ.shape[0] // ratio, ratio, occ.shape[1] // ratio, ratio).any(axis=(1, 3))
    )
    origin = (float(lo[0]), float(lo[1]), 0.0)
    fields: list[LikelihoodField] = []
    for grid, res in ((occ, FINE), (coarse, COARSE)):
        fields.append(
            LikelihoodField(
                distance_field(grid, res, MAX_DISTANCE),
                np.zeros_like(grid),
                grid,
                res,
                origin,
                MAX_DISTANCE,
            )
        )
    return fields[0], fields[1]


def verify(
    current: int,
    candidate: int,
    points: np.ndarray,
    prior: npt.ArrayLike,
    neighbours: list[tuple[np.ndarray, np.ndarray]],
    candidate_pose: npt.ArrayLike,
    travel: float,
    params: LoopParams,
) -> LoopCheck:
    """Match keyframe ``current``'s scan ``points`` near ``prior`` (its estimate) against the
    local map of ``neighbours`` (``(pose, points)`` of the candidate's neighbouring keyframes,
    at their estimates) and judge the match (module docstring). ``candidate_pose``: the
    candidate's estimate (the loop edge is from it to the match); ``travel``: metres of path
    between the two keyframes."""
    start = np.asarray(prior, dtype=np.float64)
    cpose = np.asarray(candidate_pose, dtype=np.float64)
    lin, ang = params.windows(travel)
    dist = float(math.hypot(*(start[:2] - cpose[:2])))

    def check(reason: str, **got: Any) -> LoopCheck:
        return LoopCheck(current, candidate, travel, dist, (lin, ang), reason == "accepted", reason, **got)

    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.shape[0] < params.min_points:
        return check(f"points {pts.shape[0]} < {params.min_points}")
    if not neighbours:
        return check("no local map")
    world = np.concatenate([transform_points(p, q) for p, q in neighbours])
    fine, coarse = local_field(world, lin + 1.0)
    search = ScanMatcher(
        MatchParams(
            sigmas=(0.2, 0.1),
            search="always",
            linear_window=lin,
            angular_window=ang,
            angular_step=0.01,
        )
    )
    refine = ScanMatcher(MatchParams(sigmas=(0.2, 0.1, 0.05), iterations=10, search="never"))
    m0 = fine.to_map(start)
    found = search.search(MatchField(coarse, (0.2, 0.1)), pts[::2].copy(), m0)
    mf = MatchField(fine, (0.2, 0.1, 0.05))
    pose_m, fit, H = refine.refine(mf, pts, found)
    pose = fine.to_world(pose_m)
    d = between(start, pose)
    shift = (float(math.hypot(d[0], d[1])), float(abs(d[2])))
    ij = np.floor(transform_points(pose_m, pts) / FINE).astype(int)
    rows, cols = fine.shape
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < cols) & (ij[:, 1] >= 0) & (ij[:, 1] < rows)
    near = np.zeros(pts.shape[0], dtype=bool)
    near[inside] = fine.distance[ij[inside, 1], ij[inside, 0]] <= params.inlier_distance
    inliers = float(near.mean())
    eig = np.linalg.eigvalsh(H[:2, :2])
    constraint = float(eig[0] / eig[1]) if eig[1] > 0 else 0.0
    got = {
        "fit": float(fit),
        "inliers": inliers,
        "constraint": constraint,
        "shift": shift,
        "pose": pose,
        "relative": between(cpose, pose),
    }
    if fit < params.min_fit:
        reason = f"fit {fit:.2f} < {params.min_fit}"
    elif inliers < params.min_inliers:
        reason = f"inliers {inliers:.2f} < {params.min_inliers}"
    elif shift[0] > lin + 0.05 or shift[1] > ang + 0.02:
        reason = f"outside the window: moved {shift[0]:.2f} m, {shift[1]:.2f} rad"
    elif constraint < params.min_constraint:
        reason = f"unconstrained (corridor): {constraint:.3f} < {params.min_constraint}"
    else:
        reason = "accepted"
    return check(reason, **got)
