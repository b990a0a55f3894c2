"""``loci localize`` as a user types it: a recording of the test world (a CARMEN log with
reference poses, imported), the world's map, global localization and pose tracking; what it
writes decodes and validates."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest
from support.localization_world import drifting_odometry, labels, path, scans, world
from test_import_cli import loci

from agent.bus.schemas import SCHEMAS
from agent.recording.importer import import_log
from agent.recording.replay import McapMessages
from knowledge.labels import write_label_image


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    tmp = tmp_path_factory.mktemp("localize")
    g = world()
    truth = path(0.1)
    R = scans(g, truth)
    odo = drifting_odometry(truth, drift=0.01, scale=1.01)
    lines = ["PARAM robot_frontlaser_offset 0.0 100.0 bot 100.0"]
    for i in range(len(truth)):
        t = 1000.0 + 0.2 * i
        o = " ".join(f"{v:.5f}" for v in odo[i])
        p = " ".join(f"{v:.5f}" for v in truth[i])
        r = " ".join(f"{v:.3f}" for v in R[i])
        lines.append(f"TRUEPOS {p} {o} {t:.6f} bot {t - 999.9:.6f}")
        lines.append(f"FLASER 181 {r} {o} {o} {t:.6f} bot {t - 999.9:.6f}")
    log = tmp / "world.log.gz"
    with gzip.open(log, "wt") as f:
        f.write("\n".join(lines) + "\n")
    rec = tmp / "world.mcap"
    import_log(log, rec, emit=lambda s: None)
    yaml = g.save(tmp / "world.yaml")
    lab = tmp / "world.labels.png"
    write_label_image(lab, labels(g))
    return rec, yaml, lab


def test_global_localization_with_labels_writes_validated_messages(recording: tuple, tmp_path: Path) -> None:
    rec, yaml, lab = recording
    out = tmp_path / "loc.mcap"
    done = loci(
        "localize", yaml, "--recording", rec, "--labels", lab, "--particles", "4000", "--out", out, "--json"
    )
    assert done.returncode == 0, done.stderr
    s = json.loads(done.stdout)
    assert s["mode"] == "global" and s["semantic"] is True and s["updates"] > 50
    assert s["truth"]["final_error"] < 0.3 and s["truth"]["converged_at_scan"] is not None
    kinds: dict[str, int] = {}
    for msg in McapMessages(out):
        stream = msg.topic.split("/", 2)[2]
        kinds[stream] = kinds.get(stream, 0) + 1
        if stream == "localization/pose":
            doc = SCHEMAS.decode(msg.data, "loci.pose/1")
            assert len(doc["covariance"]) == 9
    assert kinds["localization/pose"] == kinds["localization/scene"] == kinds["tf/map"] == s["updates"]


def test_global_localization_with_the_semantic_proposal(recording: tuple) -> None:
    rec, yaml, lab = recording
    done = loci(
        "localize", yaml, "--recording", rec, "--labels", lab, "--particles", "2000", "--semantic-proposal",
        "--semantic-history", "10", "--semantic-recovery", "--semantic-weight", "0.3", "--semantic-reset", "1",
        "--json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    s = json.loads(done.stdout)
    assert s["semantic"] is True and s["truth"]["final_error"] < 0.3
    assert s["truth"]["converged_at_scan"] is not None
    bad = loci("localize", yaml, "--recording", rec, "--labels", lab, "--semantic-observation", "votes")
    assert bad.returncode == 2 and "votes" in bad.stderr
    bad = loci("localize", yaml, "--recording", rec, "--semantic-distance", "-1")
    assert bad.returncode == 2 and "semantic_distance" in bad.stderr


def test_tracking_from_an_initial_pose_and_bad_arguments(recording: tuple, tmp_path: Path) -> None:
    rec, yaml, _ = recording
    start = path(0.1)[0]
    done = loci(
        "localize", yaml, "--recording", rec, "--initial", str(start[0]), str(start[1]),
        str(math.degrees(start[2])), "--particles", "1000", "--json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    s = json.loads(done.stdout)
    assert s["mode"] == "tracking" and s["truth"]["converged_at_scan"] is not None
    assert s["truth"]["final_error"] < 0.3
    bad = loci("localize", yaml, "--recording", tmp_path / "missing.mcap")
    assert bad.returncode == 2 and "missing.mcap" in bad.stderr
    wrong = tmp_path / "wrong.png"
    write_label_image(wrong, np.zeros((5, 5), dtype=np.uint8))
    bad = loci("localize", yaml, "--recording", rec, "--labels", wrong)
    assert bad.returncode == 2 and "labels for a" in bad.stderr
