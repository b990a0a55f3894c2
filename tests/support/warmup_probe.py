"""A fresh process's view of the warm-up: which kernels a realistic drive still compiles after it.

``python -m support.warmup_probe`` (run from ``tests/`` on the path) warms up as the agent does
(:func:`agent.core.warmup.warm_up`, people and tracking on), notes the signatures of every
numba function of the project, then drives a generated building — corridor, through a door
into a room and back — with a person walking ahead of the robot, drifting odometry, pose
tracking on its own thread (lag 3, the agent's default), a front laser and then a 360° one,
and prints one JSON object: the kernels that gained a signature during the drive (what the
warm-up missed) and how many scans masked a person (that the drive took that path at all).
"""

from __future__ import annotations

import json
import math

import numpy as np

from agent.core.pipeline import Pipeline, PipelineParams
from agent.core.warmup import compiled_kernels, warm_up
from drivers.messages import LaserScan, Pose2D
from knowledge.localization.tracking import TrackingParams
from knowledge.metric.raycast import cast
from knowledge.places.model import PlaceModel, default_model_path
from sim.buildings import generate_building
from sim.lms_world import ray_circle_ranges


def drive_poses() -> tuple[object, np.ndarray]:
    """A building and poses every 4 cm through one of its doors and back (test_pipeline's route)."""
    import itertools

    building = generate_building(1, furniture=False, layout="straight")
    for door in building.doors:
        if building.space(door.connects[1]).kind != "corridor":
            continue
        n = np.array([math.cos(door.orientation), math.sin(door.orientation)])
        along = np.array([-n[1], n[0]])
        c = np.array(door.center)
        x0, y0, x1, y1 = building.space(door.connects[1]).rect
        front = c + n * float(np.dot(np.array([(x0 + x1) / 2, (y0 + y1) / 2]) - c, n))
        room = np.array(building.space(door.connects[0]).center)
        waypoints = [front + 4.0 * along, front, c - 1.2 * n, room, c - 1.2 * n, front, front - 4.0 * along]
        poses: list[tuple[float, float, float]] = []
        heading: float | None = None
        for a, b in itertools.pairwise(waypoints):
            d = b - a
            h = math.atan2(d[1], d[0])
            if heading is not None:
                turn = math.atan2(math.sin(h - heading), math.cos(h - heading))
                k = int(abs(turn) / math.radians(5))
                poses += [(a[0], a[1], heading + turn * j / (k + 1)) for j in range(1, k + 1)]
            m = max(1, int(np.hypot(*d) / 0.04))
            poses += [(a[0] + d[0] * j / m, a[1] + d[1] * j / m, h) for j in range(m)]
            heading = h
        p = np.array(poses)
        cells = building.grid.world_to_cell(p[:, :2])
        if building.grid.free[cells[:, 0], cells[:, 1]].all():
            return building, p
    raise AssertionError("no door of building 1 has a free route from the corridor")


def main() -> None:
    model = PlaceModel.load(default_model_path())
    params = PipelineParams(localization=TrackingParams(), tracking_lag=3, tracking_smoothing=0.25)
    building, poses = drive_poses()
    rng = np.random.default_rng(3)
    lasers = {
        "front": (361, math.pi, -math.pi / 2, math.pi / 360),
        "360": (360, 2 * math.pi, 0.0, 2 * math.pi / 360),
    }
    rays = {
        name: cast(building.grid, poses, n_beams=n, fov=fov, max_range=30.0, noise_std=0.01, rng=rng)
        for name, (n, fov, _, _) in lasers.items()
    }
    warm_up(model, params)
    before = compiled_kernels()  # after the probe's own ray casting: only the chain's kernels count
    # odometry: the true path with a slowly growing drift
    drift = np.cumsum(rng.normal(0.0, 0.004, (len(poses), 3)) * [1, 1, 0.3], axis=0)
    masked = 0
    for laser, (n, _, angle_min, inc) in lasers.items():
        raw = rays[laser]
        pipeline = Pipeline(model, params)
        try:
            for i, (x, y, th) in enumerate(poses):
                # a person 1.3 m ahead of the robot, walking with it, legs swinging
                swing = 0.12 * math.sin(0.9 * i)
                ahead = np.array([x + 1.3 * math.cos(th), y + 1.3 * math.sin(th)])
                side = np.array([-math.sin(th), math.cos(th)])
                fwd = np.array([math.cos(th), math.sin(th)])
                legs = np.array([ahead + 0.11 * side + swing * fwd, ahead - 0.11 * side - swing * fwd])
                ranges = np.minimum(
                    raw[i],
                    ray_circle_ranges((x, y), th + angle_min + inc * np.arange(n), legs, np.full(2, 0.06)),
                )
                stamp = 1.7e9 + i / 37.5
                scan = LaserScan(stamp, i + 1, "laser", angle_min, inc, 30.0, ranges.astype(np.float32))
                o = poses[i] + drift[i]
                result = pipeline.process(scan, Pose2D(float(o[0]), float(o[1]), float(o[2]), stamp=stamp))
                masked += result.masked is not None
        finally:
            pipeline.close()
    after = compiled_kernels()
    missed = sorted(k for k, v in after.items() if v > before.get(k, 0))
    print(json.dumps({"missed": missed, "masked": masked, "scans": 2 * len(poses), "kernels": len(after)}))


if __name__ == "__main__":
    main()
