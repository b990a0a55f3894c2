"""A generated run (odometry at 50 Hz, 360° scans at 10 Hz) written as the recorder writes it, and the loci CLI in a subprocess."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agent.bus.bridge import RawSample
from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC
from agent.core.pipeline import Pipeline, PipelineParams
from agent.recording.recorder import McapSink
from drivers.messages import LaserScan, Pose2D
from knowledge.metric.raycast import cast
from knowledge.places.model import PlaceModel
from sim.buildings import generate_building
from support.cli import loci  # noqa: F401  (the tests import it from here too)

REPO = Path(__file__).resolve().parents[2]


ROBOT = "rosie"


T0 = 1.75e9


@dataclass
class Run:
    scans: list[LaserScan]
    poses: list[Pose2D]  # odometry, 50 Hz
    scan_poses: list[Pose2D]  # the odometry sample at each scan's stamp


def make_run() -> Run:
    """10 s along a generated corridor: odometry at 50 Hz, a 360° scan every 0.1 s."""
    b = generate_building(3, furniture=False, layout="straight")
    x0, y0, _, y1 = b.corridors[0].rects[0]
    y = (y0 + y1) / 2
    stamps = T0 + 0.02 * np.arange(500)  # 10 s at 50 Hz, 0.6 m/s
    xs = x0 + 1.0 + 0.6 * (stamps - T0)
    poses = [Pose2D(float(x), y, 0.0, stamp=float(t)) for x, t in zip(xs, stamps, strict=True)]
    scan_poses = poses[::5]
    rng = np.random.default_rng(3)
    arr = np.array([p.as_array() for p in scan_poses])
    raw = cast(b.grid, arr, n_beams=360, max_range=30.0, noise_std=0.01, rng=rng)
    scans = [
        LaserScan(p.stamp, i, "laser", 0.0, 2 * math.pi / 360, 30.0, raw[i]) for i, p in enumerate(scan_poses)
    ]
    return Run(scans, poses, scan_poses)


def write_recording(
    path: Path,
    run: Run,
    *,
    metadata: dict[str, str] | None = None,
    garbage: bool = False,
    until: float = math.inf,
) -> None:
    """The run as the recorder writes it: odometry arrives 3 ms after its stamp, scans 8 ms."""
    events: list[tuple[int, str, bytes, str]] = []
    for p in run.poses:
        events.append((int((p.stamp + 0.003) * 1e9), "odom", POSE_CODEC.encode(p), POSE_CODEC.zenoh_encoding))
    for s in run.scans:
        enc = LASER_SCAN_CODEC.encode(s)
        events.append((int((s.stamp + 0.008) * 1e9), "scan", enc, LASER_SCAN_CODEC.zenoh_encoding))
    if garbage:
        events.append((int((T0 + 1.0011) * 1e9), "odom", b"\xff\x00garbage", POSE_CODEC.zenoh_encoding))
    events.sort()
    with McapSink(path, metadata=metadata, chunk_size=16 * 1024) as sink:
        for t, stream, data, encoding in events:
            if t * 1e-9 <= until:
                sink.write(RawSample(f"loci/{ROBOT}/{stream}", data, encoding, t))


def expected(
    model: PlaceModel, run: Run, params: PipelineParams | None = None, n: int | None = None
) -> Pipeline:
    p = Pipeline(model, params)
    for scan, pose in list(zip(run.scans, run.scan_poses, strict=True))[:n]:
        p.process(scan, pose)
    return p
