"""The agent's configuration file for a test robot, a scan cast in a room, and ``loci run``
in a subprocess."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from drivers.messages import LaserScan
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast

ROBOT = "testbot"
REPO = Path(__file__).resolve().parents[2]


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


class AgentProcess:
    """``loci run`` in a subprocess; stderr is collected by a thread."""

    def __init__(self, config: Path, *extra: str) -> None:
        self.lines: list[str] = []
        self.ready = threading.Event()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "agent.cli", "run", "--config", str(config), *extra],
            cwd=REPO,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
        )
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line)
            if line.startswith("running robot"):
                self.ready.set()

    def wait_ready(self, timeout: float = 30.0) -> None:
        if not self.ready.wait(timeout):
            self.kill()
            raise AssertionError("loci run did not start:\n" + "".join(self.lines))

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 15.0) -> int:
        self.proc.send_signal(sig)
        rc = self.proc.wait(timeout)
        time.sleep(0.1)  # the reader thread takes the last lines
        return rc

    def summary(self) -> dict[str, Any]:
        line = next(x for x in reversed(self.lines) if x.startswith("summary: "))
        return json.loads(line[len("summary: ") :])

    def kill(self) -> None:
        """SIGKILL (no shutdown code runs), then reap."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)
