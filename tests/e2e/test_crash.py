"""A kill loses nothing the robot acknowledged, and a restarted robot never answers from an
empty map (issue 25): ``tools/crash.py``'s probe, short.

``loci run`` on the simulated robot driving a generated building (the conceptual map on), a
tutor naming the place every ~2 s and answering the robot's questions about doors, a querier
asking ``state/graph`` every 0.1 s; the agent is killed with SIGKILL by its pid right after
an acknowledgement, during its start (while it resumes the saved map and the conceptual
map), and mid-run, and started again on the same state folder. ``make fuzz`` runs 50 kills.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tools.crash import run_crashes


@pytest.mark.slow
def test_no_acknowledged_fact_is_lost_and_no_restart_answers_from_an_empty_map(tmp_path: Path) -> None:
    report = run_crashes(4, seed=1, work=tmp_path, modes=("ack", "startup", "ack", "run"))
    summary = {k: v for k, v in report.to_json().items() if k != "kills"}
    assert [k.mode for k in report.kills] == ["ack", "startup", "ack", "run"]
    assert report.acknowledged >= 2, summary  # each "ack" kill came after an acknowledgement
    assert report.lost == [], summary
    assert report.empty_answers == 0, summary
    assert report.corrupt == [], summary
    # every start answered "starting" before its map was loaded (never an empty map)
    assert report.starting_answers > 0, summary
    assert report.graph_answers > report.starting_answers, summary
