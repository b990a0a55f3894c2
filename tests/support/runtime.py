"""The agent's configuration file for a test robot, and a scan cast in a room."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from drivers.messages import LaserScan
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast

ROBOT = "testbot"


def write_config(tmp_path: Path, endpoint: str, port: Path | None, **extra: str) -> Path:
    laser = f'port = "{port}"' if port is not None else 'source = "bus"'
    text = f"""
[robot]
name = "{ROBOT}"

[bus]
listen = ["tcp/127.0.0.1:0"]
connect = ["{endpoint}"]

[laser]
{laser}

[state]
dir = "state"
save_interval = 0.3
"""
    for section, body in extra.items():
        text += f"\n[{section}]\n{body}\n"
    path = tmp_path / "robot.toml"
    path.write_text(text)
    return path


def _room_scan(grid: OccupancyGrid, pose: tuple[float, float, float], stamp: float, seq: int) -> LaserScan:
    ranges = cast(grid, np.array(pose), n_beams=360, max_range=30.0)
    return LaserScan(stamp, seq, "laser", 0.0, 2 * math.pi / 360, 30.0, ranges)
