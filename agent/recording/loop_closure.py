"""Loop closure on a recording, offline: replay with pose tracking, close loops, measure.

:func:`collect_tracked` replays a recording through the agent's pipeline
(:func:`~agent.recording.offline.replay_recording`) with pose tracking on — as
``loci replay --config deploy/robot.toml`` turns it on, but with the tracker in the per-scan
path (``lag`` 0, no smoothing), so that each scan's pose is the tracker's own for that scan —
and keeps, per processed scan, the beam endpoints, the laser's odometry pose and its tracked
pose; and the recording's reference poses (``pose/truth``, ``loci import --reference``).

:func:`evaluate_loop_closure` runs the pose graph of
:mod:`knowledge.localization.pose_graph` over those scans and reports the absolute
trajectory error (ATE, :func:`~knowledge.localization.trajectory.ate`) of the raw odometry,
of the tracked poses and of the optimised poses against the reference, at the reference's
scans. Not wired into the live runtime or ``loci replay`` yet (docs/mapping.md).
"""

from __future__ import annotations

import itertools
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from knowledge.localization.scan_matching import scan_points
from knowledge.localization.se2 import compose, inverse

__all__ = ["LoopClosureReport", "TrackedRun", "collect_tracked", "evaluate_loop_closure"]


@dataclass(frozen=True, eq=False)
class TrackedRun:
    """The processed scans of a replay with tracking (``n`` of them).

    Attributes:
        name: the recording's file name.
        stamps: ``(n,)`` seconds.
        points: ``n`` arrays ``(M_i, 2)`` of beam endpoints in the laser's frame, metres.
        odom: ``(n, 3)`` the laser's odometry pose.
        tracked: ``(n, 3)`` the laser's pose the tracker gave (frame ``map``).
        truth_stamps, truth: ``(m,)`` and ``(m, 3)`` the reference poses of the laser
            (``m = 0`` when the recording has none).
        replay_seconds: wall-clock seconds the replay took.
    """

    name: str
    stamps: np.ndarray
    points: list[np.ndarray]
    odom: np.ndarray
    tracked: np.ndarray
    truth_stamps: np.ndarray
    truth: np.ndarray
    replay_seconds: float = 0.0

    def __len__(self) -> int:
        return len(self.points)

    def truth_index(self, tolerance: float = 1e-3) -> np.ndarray:
        """``(m', 2)`` pairs (scan index, truth index) of equal stamps."""
        from knowledge.localization.trajectory import associate

        return associate(self.stamps, self.truth_stamps, tolerance)

    def save(self, path: Path) -> None:
        """As an ``.npz`` (no pickle: the endpoints are one array with offsets)."""
        counts = np.array([p.shape[0] for p in self.points], dtype=np.int64)
        np.savez(
            path,
            name=np.array(self.name),
            stamps=self.stamps,
            points=np.concatenate(self.points) if self.points else np.zeros((0, 2)),
            counts=counts,
            odom=self.odom,
            tracked=self.tracked,
            truth_stamps=self.truth_stamps,
            truth=self.truth,
            replay_seconds=np.float64(self.replay_seconds),
        )

    @classmethod
    def load(cls, path: Path) -> TrackedRun:
        with np.load(path, allow_pickle=False) as z:
            offsets = np.concatenate([[0], np.cumsum(z["counts"])])
            pts = z["points"]
            return cls(
                name=str(z["name"]),
                stamps=z["stamps"],
                points=[pts[a:b] for a, b in itertools.pairwise(offsets)],
                odom=z["odom"],
                tracked=z["tracked"],
                truth_stamps=z["truth_stamps"],
                truth=z["truth"],
                replay_seconds=float(z["replay_seconds"]),
            )


def collect_tracked(
    path: str | Path,
    *,
    tracking: Any = None,
    max_range: float = 20.0,
    duration: float | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> TrackedRun:
    """Replay ``path`` with pose tracking and keep what loop closure needs (module docstring).

    Args:
        path: the MCAP recording.
        tracking: :class:`~knowledge.localization.tracking.TrackingParams` (default: the defaults).
        max_range: metres; longer beams are not kept as endpoints.
        duration: replay only the first seconds of the recording.
        progress: ``progress(stage, done, total)``.
    """
    from agent.core.pipeline import PipelineParams, StepResult
    from agent.recording.localize import read_truth
    from agent.recording.offline import read_recording_metadata, replay_recording
    from knowledge.localization.tracking import TrackingParams

    p = Path(path)
    meta = read_recording_metadata(p)
    base = (
        PipelineParams.from_table(json.loads(meta["pipeline"])) if meta.get("pipeline") else PipelineParams()
    )
    params = replace(base, localization=tracking or TrackingParams(), tracking_lag=0, tracking_smoothing=0.0)
    stamps: list[float] = []
    points: list[np.ndarray] = []
    odom: list[np.ndarray] = []
    tracked: list[np.ndarray] = []

    def on_step(result: StepResult) -> None:
        s = result.scan
        pose = np.array([result.pose.x, result.pose.y, result.pose.theta])
        corr = np.zeros(3) if result.correction is None else np.asarray(result.correction)
        stamps.append(s.stamp)
        tracked.append(pose)
        odom.append(compose(inverse(corr), pose))
        points.append(
            scan_points(
                s.ranges, s.angles, range_max=s.range_max, range_min=s.range_min, max_range=max_range
            ).astype(np.float32)
        )

    t0 = time.perf_counter()
    out = replay_recording(p, params=params, on_step=on_step, progress=progress, duration=duration)
    seconds = time.perf_counter() - t0
    robot = meta.get("robot") or ""
    t_stamps, t_poses = read_truth(p, robot) if robot else (np.zeros(0), np.zeros((0, 3)))
    if t_poses.shape[0]:
        t_poses = compose(t_poses, np.asarray(out.pipeline.params.mount))
    return TrackedRun(
        name=p.name,
        stamps=np.asarray(stamps, dtype=np.float64),
        points=points,
        odom=np.asarray(odom, dtype=np.float64).reshape(-1, 3),
        tracked=np.asarray(tracked, dtype=np.float64).reshape(-1, 3),
        truth_stamps=t_stamps,
        truth=t_poses.reshape(-1, 3),
        replay_seconds=seconds,
    )


@dataclass(frozen=True)
class LoopClosureReport:
    """What :func:`evaluate_loop_closure` measured (ATE: RMSE metres after the best rigid
    alignment, at the scans that have a reference pose).

    Attributes:
        scans, keyframes, references: how many of each.
        checks, loops: candidates verified, loops accepted.
        ate_odometry, ate_tracked, ate_optimised: the ATE of each trajectory at every
            reference scan (the optimised one places each scan from its keyframe).
        ate_keyframes: the optimised keyframes' own ATE, at those that have a reference pose
            (NaN when fewer than 3 have); ate_tracked_keyframes: the tracked poses' there.
        keyframe_references: keyframes with a reference pose.
        optimisation_ms: ``(mean, max)`` milliseconds per optimisation (0 when none ran).
        iterations_max: the most Levenberg–Marquardt iterations one optimisation took.
        seconds: wall-clock seconds of the pose graph over the whole run.
        reasons: why candidates were rejected, counted by the test that failed.
    """

    scans: int
    keyframes: int
    references: int
    checks: int
    loops: int
    ate_odometry: float
    ate_tracked: float
    ate_optimised: float
    ate_keyframes: float
    ate_tracked_keyframes: float
    keyframe_references: int
    optimisation_ms: tuple[float, float]
    iterations_max: int
    seconds: float
    reasons: dict[str, int]

    def as_dict(self) -> dict[str, Any]:
        from dataclasses import asdict

        return asdict(self)


def evaluate_loop_closure(
    run: TrackedRun, params: Any = None, *, source: str = "tracked"
) -> tuple[LoopClosureReport, Any]:
    """Feed ``run``'s scans to a :class:`~knowledge.localization.pose_graph.PoseGraph` with
    the ``source`` poses (``"tracked"`` or ``"odometry"``) and measure it against the
    reference; returns the report and the graph.

    Raises:
        DataError: the recording has no reference poses at its scans.
    """
    from knowledge.errors import DataError
    from knowledge.localization.pose_graph import PoseGraph, PoseGraphParams
    from knowledge.localization.trajectory import ate

    if source not in ("tracked", "odometry"):
        raise ValueError(f"source must be 'tracked' or 'odometry', got {source!r}")
    pairs = run.truth_index()
    if pairs.shape[0] < 3:
        raise DataError(
            f"{run.name}: {pairs.shape[0]} scans have a reference pose; import it with "
            "loci import LOG OUT.mcap --reference CORRECTED"
        )
    poses = run.tracked if source == "tracked" else run.odom
    graph = PoseGraph(params or PoseGraphParams())
    t0 = time.perf_counter()
    for i in range(len(run)):
        graph.add(float(run.stamps[i]), poses[i], run.points[i])
    seconds = time.perf_counter() - t0
    corrected = graph.corrected()
    scans, refs = pairs[:, 0], run.truth[pairs[:, 1]]

    def rmse(est: np.ndarray, ref: np.ndarray = refs) -> float:
        return float(ate(ref, est)[0].rmse)

    by_scan = {int(s): int(t) for s, t in pairs}
    kf = [(i, by_scan[k.scan]) for i, k in enumerate(graph.keyframes) if k.scan in by_scan]
    if len(kf) >= 3:
        ki, ti = (np.array(c) for c in zip(*kf, strict=True))
        ate_kf = rmse(graph.estimates[ki], run.truth[ti])
        ate_kf_tracked = rmse(run.tracked[[graph.keyframes[i].scan for i in ki]], run.truth[ti])
    else:
        ate_kf = ate_kf_tracked = float("nan")
    reasons: dict[str, int] = {}
    for c in graph.checks:
        key = c.reason.split(" ")[0].rstrip(":")
        reasons[key] = reasons.get(key, 0) + 1
    ms = np.array(graph.optimisations) * 1000.0
    report = LoopClosureReport(
        scans=len(run),
        keyframes=len(graph),
        references=int(pairs.shape[0]),
        checks=len(graph.checks),
        loops=len(graph.loops),
        ate_odometry=rmse(run.odom[scans]),
        ate_tracked=rmse(run.tracked[scans]),
        ate_optimised=rmse(corrected[scans]),
        ate_keyframes=ate_kf,
        ate_tracked_keyframes=ate_kf_tracked,
        keyframe_references=len(kf),
        optimisation_ms=(float(ms.mean()), float(ms.max())) if ms.size else (0.0, 0.0),
        iterations_max=max(graph.iterations, default=0),
        seconds=seconds,
        reasons=reasons,
    )
    return report, graph
