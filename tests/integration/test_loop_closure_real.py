"""Loop closure on the raw MIT CSAIL log (real data; skipped without ../shared/data)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agent.recording.importer import import_log
from agent.recording.loop_closure import TrackedRun, collect_tracked, evaluate_loop_closure
from agent.recording.reference import add_reference
from knowledge.localization.se2 import between, compose

pytestmark = pytest.mark.data


@pytest.mark.slow
def test_the_first_loops_of_csail_agree_with_the_reference(shared_data: Path, tmp_path: Path) -> None:
    """The first 75 s of the raw log (the robot is back where it started after 59 s): the
    replay with tracking, its keyframes and loops; the loops agree with the corrected poses,
    and the optimised poses are no worse than the tracked ones."""
    logs = shared_data / "logs"
    raw, rec = tmp_path / "raw.mcap", tmp_path / "csail.mcap"
    import_log(logs / "csail-oldcarmen.log.gz", raw, emit=lambda s: None)
    add_reference(raw, logs / "csail-corrected.log.gz", rec)
    run = collect_tracked(rec, duration=75.0)
    assert 250 < len(run) < 450 and run.truth.shape[0] > 50
    # the arrays survive a round trip through the cache file
    run.save(tmp_path / "run.npz")
    back = TrackedRun.load(tmp_path / "run.npz")
    assert np.array_equal(back.tracked, run.tracked) and all(
        np.array_equal(a, b) for a, b in zip(back.points, run.points, strict=True)
    )
    report, graph = evaluate_loop_closure(run)
    assert report.loops >= 1, report.reasons
    # every loop agrees with the reference: a keyframe's reference pose is that of the nearest
    # scan that has one, moved by the tracked motion between the two (a few centimetres of it)
    pairs = run.truth_index()

    def reference(scan: int) -> np.ndarray:
        s, t = pairs[np.argmin(np.abs(pairs[:, 0] - scan))]
        return compose(run.truth[t], between(run.tracked[s], run.tracked[scan]))

    kf = graph.keyframes
    for j, k, rel in graph.loops:
        err = between(between(reference(kf[j].scan), reference(kf[k].scan)), rel)
        assert np.hypot(err[0], err[1]) < 0.15 and abs(err[2]) < 0.03, (j, k, err)
    assert report.ate_tracked < 0.15
    assert report.ate_optimised <= report.ate_tracked + 0.01
    assert report.ate_odometry > 3 * report.ate_optimised
    assert report.optimisation_ms[1] < 1000 * graph.params.max_seconds + 200
