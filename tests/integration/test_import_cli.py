"""``loci import`` as a user types it, then ``loci replay`` on what it wrote; a ROS 2 MCAP bag
straight into ``loci replay``; --strict, --json, --force, options of the wrong kind; the
progress bar on a real terminal (a pty) and not elsewhere."""

from __future__ import annotations

import gzip
import json
import math
import os
import pty
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support.cli import loci

REPO = Path(__file__).resolve().parents[2]


def box_ranges(x: float, y: float, theta: float, n: int = 181, box=(-1.0, 30.0, -1.5, 1.5)) -> np.ndarray:
    """Ranges (m) of a 180° laser at (x, y, theta) inside an axis-aligned box (a corridor)."""
    a = theta + np.linspace(-math.pi / 2, math.pi / 2, n)
    dx, dy = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dx > 0, (box[1] - x) / dx, np.where(dx < 0, (box[0] - x) / dx, np.inf))
        ty = np.where(dy > 0, (box[3] - y) / dy, np.where(dy < 0, (box[2] - y) / dy, np.inf))
    return np.minimum(np.minimum(tx, ty), 81.91)


def corridor_log(path: Path, scans: int = 60, extra: list[str] | None = None) -> Path:
    """A CARMEN log of a robot driving 0.1 m per scan down a corridor (FLASER + ODOM, gzipped)."""
    lines = ["# CARMEN Logfile", "PARAM robot_frontlaser_offset 0.0 100.0 bot 100.0"]
    for i in range(scans):
        t = 1000.0 + 0.2 * i
        x = 0.1 * i
        lines.append(f"ODOM {x:.4f} 0.0 0.0 0.5 0.0 0.0 {t - 0.1:.6f} bot {t - 999.99:.6f}")
        r = " ".join(f"{v:.2f}" for v in box_ranges(x, 0.0, 0.0))
        lines.append(f"FLASER 181 {r} {x:.4f} 0 0 {x:.4f} 0 0 {t:.6f} bot {t - 999.95:.6f}")
    lines += extra or []
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")
    return path


@pytest.mark.slow
def test_import_then_replay_as_a_user_types_it(tmp_path: Path) -> None:
    log = corridor_log(tmp_path / "corridor.log.gz")
    out = tmp_path / "corridor.mcap"
    r = loci("import", log, out)
    assert r.returncode == 0, r.stderr
    assert (
        "122 lines read = 60 imported (60 scans, 60 odometry, 0 reference poses) + 62 skipped" in r.stdout
    ), r.stdout
    assert "(60 odometry_not_used, 1 comment, 1 param)" in r.stdout and f"loci replay {out}" in r.stdout
    assert "\r" not in r.stderr and "import:" not in r.stderr  # no progress bar without a terminal
    r = loci("replay", out)
    assert r.returncode == 0, r.stderr
    assert "replayed" in r.stdout and "60 scans = 60 processed + 0 dropped" in r.stdout, r.stdout
    # the same file again: refused without --force
    r = loci("import", log, out)
    assert r.returncode == 2 and "exists" in r.stderr and "--force" in r.stderr
    r = loci("import", log, out, "--force", "--json", "--odometry", "odom", "--robot", "rosie")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["robot"] == "rosie" and doc["stats"]["written"] == {"odom": 60, "scan": 60}
    assert doc["stats"]["read"] == doc["stats"]["imported"] + sum(doc["stats"]["skipped"].values())


@pytest.mark.slow
def test_strict_stops_at_the_first_bad_line(tmp_path: Path) -> None:
    log = corridor_log(
        tmp_path / "bad.log.gz", scans=5, extra=["FLASER 3 1.0 nan 2.0 0 0 0 0 0 0 1002.0 bot 2.1"]
    )
    out = tmp_path / "bad.mcap"
    r = loci("import", log, out)
    assert r.returncode == 0, r.stderr
    assert "warning: bad.log.gz line 13: 1 of 3 ranges are NaN" in r.stderr, r.stderr
    assert "kept with a warning: 1 bad_ranges" in r.stdout
    r = loci("import", log, tmp_path / "strict.mcap", "--strict")
    assert r.returncode == 2 and "line 13" in r.stderr and "--strict" in r.stderr, r.stderr
    assert not (tmp_path / "strict.mcap").exists()


def test_options_of_the_other_kind_and_unknown_inputs_are_refused(tmp_path: Path) -> None:
    log = corridor_log(tmp_path / "c.log.gz", scans=3)
    r = loci("import", log, tmp_path / "a.mcap", "--scan-topic", "/scan")
    assert r.returncode == 2 and "for ROS bags, not CARMEN logs" in r.stderr
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)))
    r = loci("import", junk, tmp_path / "b.mcap")
    assert r.returncode == 2 and "not a CARMEN log" in r.stderr
    r = loci("import", log, tmp_path / "c.mcap", "--mount", "0.1 0")
    assert r.returncode == 2 and "X Y YAW" in r.stderr


@pytest.mark.slow
def test_a_ros2_mcap_bag_replays_straight(tmp_path: Path) -> None:
    from support.bags import write_standard_bag

    bag_dir = write_standard_bag(tmp_path, "ros2-mcap")
    (mcap,) = bag_dir.glob("*.mcap")
    r = loci("replay", mcap)
    assert r.returncode == 0, r.stderr
    assert "is a ROS 2 bag: imported it first" in r.stderr
    assert "10 scans = 10 processed + 0 dropped; 21 odometry messages" in r.stdout, r.stdout


@pytest.mark.slow
def test_progress_bar_on_a_terminal(tmp_path: Path) -> None:
    log = corridor_log(tmp_path / "long.log.gz", scans=1100)
    master, slave = pty.openpty()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "agent.cli", "import", str(log), str(tmp_path / "long.mcap")],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=slave,
            timeout=120,
            check=False,
        )
        os.close(slave)
        slave = -1
        seen = b""
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
    finally:
        if slave >= 0:
            os.close(slave)
        os.close(master)
    assert proc.returncode == 0
    assert b"import:" in seen and b"\r" in seen, seen[:300]
