"""``loci import`` on the real logs and the bag of ``../shared/data`` (skipped when absent).

Each whole file is imported (a few seconds each) and its counts checked; the replay runs on
a prefix of each CARMEN log (the whole Freiburg 079 log takes over a minute to replay, which
is the pipeline's time, not the importer's) and on the whole bag.
"""

from __future__ import annotations

import gzip
import zipfile
from pathlib import Path

import pytest
from support.cli import loci

from agent.recording.carmen import CarmenOptions
from agent.recording.imported import ODOM, SCAN, TRUTH
from agent.recording.importer import import_log
from agent.recording.offline import replay_recording

pytestmark = pytest.mark.data


def prefix(src: Path, dst: Path, lines: int) -> Path:
    """The first ``lines`` lines of a gzipped log, gzipped."""
    with gzip.open(src, "rt") as f, gzip.open(dst, "wt") as g:
        for i, line in enumerate(f):
            if i >= lines:
                break
            g.write(line)
    return dst


def replays_every_scan(path: Path, scans: int) -> None:
    out = replay_recording(path)
    assert out.scans == scans and out.pipeline.scans == scans, out.stats()
    assert out.sync["dropped"] == 0


@pytest.mark.slow
def test_freiburg_079(shared_data: Path, tmp_path: Path) -> None:
    log = shared_data / "logs" / "freiburg-079-corrected.log.gz"
    res = import_log(log, tmp_path / "fr079.mcap", emit=lambda s: None)
    s = res.stats
    assert s.balanced and s.written[SCAN] == 4791 and s.written[ODOM] == 4791 and s.written[TRUTH] == 0
    assert s.unknown_types == {"NEFF": 4791} and s.skipped["odometry_not_used"] == 9725
    assert s.beams["sick_no_return"] == 36_004 and s.beams["sick_invalid"] == 0  # every 81.91 m reading
    assert res.mount == pytest.approx((-0.04, 0.0, 0.0))  # robot_frontlaser_offset
    assert res.choices["clock"] == "ipc" and res.choices["scan_lines"] == "FLASER"
    # a prefix, with the SLAM-corrected poses as references, replays scan for scan (the whole
    # log takes over a minute in the pipeline)
    head = prefix(log, tmp_path / "fr079-head.log.gz", 1400)
    short = import_log(head, tmp_path / "head.mcap", carmen=_options(truth="laser"), emit=lambda s: None)
    n = short.stats.written[SCAN]
    assert 250 < n < 400 and short.stats.written[TRUTH] == n
    replays_every_scan(tmp_path / "head.mcap", n)


@pytest.mark.slow
def test_csail_raw(shared_data: Path, tmp_path: Path) -> None:
    log = shared_data / "logs" / "csail-oldcarmen.log.gz"
    res = import_log(log, tmp_path / "csail.mcap", emit=lambda s: None)
    s = res.stats
    assert s.balanced and s.written[SCAN] == 1988 and s.written[ODOM] == 1988
    assert res.choices["scan_lines"] == "ROBOTLASER1" and s.skipped["duplicate"] == 2 * 1988
    assert s.beams["sick_no_return"] == 23_711
    short = import_log(prefix(log, tmp_path / "head.log.gz", 1800), tmp_path / "head.mcap")
    assert short.stats.written[SCAN] > 200
    replays_every_scan(tmp_path / "head.mcap", short.stats.written[SCAN])
    # the ODOM lines as odometry (the base's own messages) replay too
    odom = import_log(tmp_path / "head.log.gz", tmp_path / "odom.mcap", carmen=_options(odometry="odom"))
    assert odom.stats.written[ODOM] > odom.stats.written[SCAN]
    out = replay_recording(tmp_path / "odom.mcap")
    assert out.pipeline.scans > 0.9 * odom.stats.written[SCAN], out.stats()


def test_csail_corrected(shared_data: Path, tmp_path: Path) -> None:
    log = shared_data / "logs" / "csail-corrected.log.gz"
    res = import_log(log, tmp_path / "csail-corr.mcap", emit=lambda s: None)
    s = res.stats
    assert s.balanced and s.written[SCAN] == 406 and s.written[ODOM] == 406
    assert res.choices["clock"].startswith("lines:")  # its times are printed as 1.13486e+09
    short = import_log(
        prefix(log, tmp_path / "head.log.gz", 1000), tmp_path / "head.mcap", emit=lambda s: None
    )
    replays_every_scan(tmp_path / "head.mcap", short.stats.written[SCAN])


@pytest.mark.slow
def test_people_bag(shared_data: Path, tmp_path: Path) -> None:
    with zipfile.ZipFile(shared_data / "people" / "general_tracking_moving_1.bag.zip") as z:
        z.extractall(tmp_path)
    (bag,) = tmp_path.glob("**/*.bag")
    res = import_log(bag, tmp_path / "people.mcap")
    s = res.stats
    assert s.balanced and s.read == 34_729 and s.written[SCAN] == 873 and s.written[ODOM] == 11_561
    assert res.choices["laser_frame"] == "left_laser" and res.choices["base_frame"] == "base_link"
    assert res.warnings == {}
    replays_every_scan(tmp_path / "people.mcap", 873)


def _options(**kw: str) -> CarmenOptions:
    return CarmenOptions(**kw)


@pytest.mark.slow
def test_loci_evaluate_log_on_a_stretch_of_freiburg_079(shared_data: Path, tmp_path: Path) -> None:
    """The CLI as a user types it, on the first 4,000 lines of the real log (about 980 scans
    along the corridor and into the first rooms) with the data set's per-scan labels and
    labelled map: every processed scan is scored, and the agent does better than chance."""
    import json

    logs = shared_data / "logs"
    head = prefix(logs / "freiburg-079-corrected.log.gz", tmp_path / "head.log.gz", 4000)
    rec = tmp_path / "head.mcap"
    import_log(head, rec, emit=lambda s: None)
    out = loci(
        "evaluate",
        "log",
        str(rec),
        "--labels",
        str(logs / "fr079_labels_provisional.npz"),
        "--label-map",
        str(logs / "Freiburg79_labels_provisional.png"),
        "--json",
    )
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    n = got["replay"]["processed"]
    assert got["replay"]["balanced"] and 900 < n < 1100
    assert got["scans"]["scored"] == n and got["scans"]["labelled"] == 4791
    two = got["scans"]["room_corridor"]
    assert two["n"] > 0.9 * n and two["balanced_accuracy"] > 0.55
    assert got["doorways"]["doors_driven_through"] >= 1 and got["areas"]["rooms_visited"] >= 1
