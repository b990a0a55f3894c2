"""The same result at any speed (issue 24), on a real log: the raw CSAIL log (drifting
odometry, tracking on) replayed as fast as possible, at real time, at real time on one core
beside a busy loop, and through the live agent (``loci run --play``) on that busy core, gives
the same poses, the same navigation graph and the same areas. The guided tour's recording
gets the same test in test_demo_noisy.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.determinism import differences, run_conditions

SECONDS = 30.0  # of the log: 150 scans at 5 Hz, the first corridor and a turn


@pytest.mark.data
@pytest.mark.slow
def test_csail_with_tracking_gives_the_same_map_at_any_speed(shared_data: Path, tmp_path: Path) -> None:
    from agent.recording.importer import import_log

    rec = tmp_path / "csail.mcap"
    import_log(shared_data / "logs" / "csail-oldcarmen.log.gz", rec, emit=lambda s: None)
    outcomes = run_conditions(
        rec, "csail-oldcarmen", tmp_path / "runs", SECONDS, "[localization]\ntracking = true\n"
    )
    diff = differences(outcomes)
    print(diff)
    ref = diff["fast"]
    assert ref["scans"] > 120 and ref["nodes"] > 5
    for c, d in diff.items():
        assert d["common"] == ref["scans"], (c, d)  # every scan, in every condition
        assert d["max_pose_m"] < 0.02, (c, d)
        assert d["same_nodes"] and d["same_edges"] and d["same_areas"], (c, d)
        assert d["labels_differ"] == 0, (c, d)
