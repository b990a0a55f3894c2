"""A recording as arrays for localization: each processed scan with its odometry, its place
histogram, and the reference poses the recording carries.

:func:`collect_run` replays a recording through the agent's pipeline
(:func:`agent.commands.replay.replay_recording`, so scans are associated with odometry and
classified exactly as ``loci replay`` does) and keeps, per processed scan, the scan, the
laser's odometry pose and the classifier's histogram; and reads ``pose/truth`` (a log's
reference poses, ``loci import --reference`` or ``--truth``), moved from the robot to the
laser by the laser's mount.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers.messages import LaserScan
from knowledge.localization.se2 import compose

__all__ = ["RunLog", "collect_run", "read_truth"]


@dataclass(frozen=True, eq=False)
class RunLog:
    """The processed scans of a replay (``n`` of them).

    Attributes:
        name: the recording's file name.
        scans: the scans as measured.
        stamps: ``(n,)`` seconds.
        odom: ``(n, 3)`` the laser's odometry pose at each scan.
        proba: ``(n, K)`` the place classifier's histograms; ``classes`` its columns.
        mount: the laser's mount on the robot ``(x, y, yaw)``.
        truth_stamps, truth: ``(m,)`` and ``(m, 3)`` the reference poses of the **laser**
            (frame ``map``); ``m = 0`` when the recording has none.
    """

    name: str
    scans: list[LaserScan]
    stamps: np.ndarray
    odom: np.ndarray
    proba: np.ndarray
    classes: tuple[str, ...]
    mount: tuple[float, float, float]
    truth_stamps: np.ndarray
    truth: np.ndarray

    def __len__(self) -> int:
        return len(self.scans)

    def truth_index(self, tolerance: float = 1e-3) -> np.ndarray:
        """``(m', 2)`` pairs (scan index, truth index) of equal stamps."""
        from knowledge.localization.trajectory import associate

        return associate(self.stamps, self.truth_stamps, tolerance)

    @property
    def labels(self) -> list[str]:
        return [self.classes[int(k)] for k in np.argmax(self.proba, axis=1)]


def read_truth(path: Path, robot: str) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps, (m, 3) poses)`` of the robot's ``pose/truth`` messages, in stamp order."""
    from agent.bus.codecs import POSE_CODEC, checked_decode
    from agent.bus.keys import stream_key
    from agent.recording.replay import McapMessages
    from knowledge.errors import ProtocolError

    key = stream_key(robot, "pose/truth")
    rows: dict[float, tuple[float, float, float]] = {}
    for msg in McapMessages(path, topics={key}):
        try:
            p = checked_decode(POSE_CODEC, msg.zenoh_encoding, msg.data, msg.topic)
        except ProtocolError:
            continue
        rows.setdefault(p.stamp, (p.x, p.y, p.theta))
    stamps = np.array(sorted(rows), dtype=np.float64)
    poses = np.array([rows[t] for t in stamps], dtype=np.float64).reshape(-1, 3)
    return stamps, poses


def collect_run(
    path: str | Path,
    *,
    model: Any = None,
    params: Any = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> RunLog:
    """Replay ``path`` through the pipeline and keep what localization needs (module docstring)."""
    from agent.core.pipeline import StepResult
    from agent.recording.offline import read_recording_metadata, replay_recording

    p = Path(path)
    scans: list[LaserScan] = []
    stamps: list[float] = []
    odom: list[np.ndarray] = []
    proba: list[list[float]] = []
    mount: list[tuple[float, float, float]] = []

    def on_step(result: StepResult) -> None:
        scans.append(result.scan)
        stamps.append(result.stamp)
        pose = result.pose
        odom.append(np.array([pose.x, pose.y, pose.theta]))
        # the classifier's own histogram (eq. 6.3 wants it), not the trajectory HMM's belief
        raw = result.raw_probabilities or result.probabilities
        proba.append(list(raw.values()))

    out = replay_recording(p, model=model, params=params, on_step=on_step, progress=progress)
    pipeline = out.pipeline
    mount.append(pipeline.params.mount)
    robot = read_recording_metadata(p).get("robot") or ""
    t_stamps, t_poses = read_truth(p, robot) if robot else (np.zeros(0), np.zeros((0, 3)))
    if t_poses.shape[0]:
        t_poses = compose(t_poses, np.asarray(pipeline.params.mount))
    return RunLog(
        name=p.name,
        scans=scans,
        stamps=np.asarray(stamps, dtype=np.float64),
        odom=np.asarray(odom, dtype=np.float64).reshape(-1, 3),
        proba=np.asarray(proba, dtype=np.float64).reshape(len(scans), -1),
        classes=tuple(pipeline.classes),
        mount=tuple(pipeline.params.mount),
        truth_stamps=t_stamps,
        truth=t_poses,
    )
