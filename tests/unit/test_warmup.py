"""The warm-up compiles every kernel of the chain before the robot moves (issue 24: a kernel
first compiled a metre into "Follow me" froze the agent's loop for 4–6 s)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np

from agent.core.warmup import CompileWatch, scenario

TESTS = Path(__file__).resolve().parents[1]


def test_after_the_warm_up_a_drive_with_a_person_ahead_compiles_nothing() -> None:
    """In a fresh process (nothing compiled by other tests): warm up, then drive a generated
    building with a person walking ahead, drifting odometry and tracking on its thread."""
    out = subprocess.run(
        [sys.executable, "-m", "support.warmup_probe"],
        cwd=TESTS,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    probe = json.loads(out.stdout.strip().splitlines()[-1])
    assert probe["masked"] > 100  # the drive took the people-masking path
    assert probe["kernels"] > 30
    assert probe["missed"] == [], probe["missed"]


def test_the_scenario_has_a_walker_ahead_and_one_odometry_jump() -> None:
    for full in (False, True):
        pairs = scenario(full)
        assert len(pairs) > 100
        scan, _ = pairs[0]
        assert scan.n_beams == (360 if full else 361)
        stamps = np.array([s.stamp for s, _ in pairs])
        assert np.all(np.diff(stamps) > 0)
        steps = np.diff([p.x for _, p in pairs])
        assert (steps > 0.3).sum() == 1  # the one jump of the odometry
        # something nearer than the corridor's walls straight ahead: the walker's legs
        ahead = np.array([s.ranges[np.argmin(np.abs(s.angles))] for s, _ in pairs])
        assert np.median(ahead) < 3.0


def test_the_compile_watch_names_a_kernel_compiled_once_armed() -> None:
    @numba.njit
    def twice(x: float) -> float:
        return 2.0 * x

    watch = CompileWatch(prefixes=(__name__,)).arm()
    try:
        assert twice(1.0) == 2.0
        assert twice(2.0) == 4.0  # the same signature: compiled once
        compiled = watch.take()
        assert [name for name, _ in compiled] == [f"{__name__}.{twice.py_func.__qualname__}"]
        assert compiled[0][1] > 0
        assert watch.take() == []
    finally:
        watch.close()
    twice(np.float32(1.0))  # after close(): not counted
    assert watch.take() == []
