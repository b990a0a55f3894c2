"""The CARMEN importer on small logs the tests write: every line type, both beam-angle
conventions, the SICK codes, each kind of bad input, --strict; read back from the MCAP file."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest

from agent.bus.codecs import decode_laser_scan, decode_pose
from agent.core.pipeline import PipelineParams
from agent.recording.carmen import (
    CarmenConverter,
    CarmenOptions,
    LaserLine,
    LineError,
    OdomLine,
    ParamLine,
    TruePosLine,
    beam_convention,
    parse_line,
    survey_lines,
    time_resolution,
)
from agent.recording.imported import ODOM, SCAN, TRUTH, Skip
from agent.recording.importer import ImportResult, import_log
from agent.recording.offline import read_recording_metadata
from agent.recording.replay import McapMessages
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import DataError


def times(t: float, host: str = "robot") -> str:
    return f"{t:.6f} {host} {t - 1000.0:.6f}"  # logger time: seconds since the logger started


def flaser(
    n: int, t: float, ranges: list[str] | None = None, pose: tuple[float, float, float] = (1, 2, 0.5)
) -> str:
    r = ranges if ranges is not None else [f"{1 + i % 7:.2f}" for i in range(n)]
    p = " ".join(f"{v:.6f}" for v in pose)
    return f"FLASER {n} {' '.join(r)} {p} {p} {times(t)}"


def odom(t: float, x: float = 1.0) -> str:
    return f"ODOM {x:.6f} 2.000000 0.500000 0.1 0.0 0.0 {times(t)}"


def robotlaser(
    t: float, n: int = 5, laser_pose=(1.0, 2.0, 0.5), robot_pose=(1.0, 2.0, 0.5), old: bool = False
) -> str:
    r = " ".join(f"{2 + i:.2f}" for i in range(n))
    head = f"0 -0.785398 1.570796 {1.570796 / (n - 1):.6f} 81.920000 0.010000" + ("" if old else " 0")
    lp = " ".join(f"{v:.6f}" for v in laser_pose)
    rp = " ".join(f"{v:.6f}" for v in robot_pose)
    return f"ROBOTLASER1 {head} {n} {r} 0 {lp} {rp} 0.1 0.0 0.5 0.3 1000000.0 {times(t)}"


def rawlaser(t: float, n: int = 5) -> str:
    r = " ".join(f"{2 + i:.2f}" for i in range(n))
    return (
        f"RAWLASER1 0 -0.785398 1.570796 {1.570796 / (n - 1):.6f} 81.920000 0.010000 0 {n} {r} 0 {times(t)}"
    )


def write_log(path: Path, lines: list[str], *, gz: bool = False, end: str = "\n") -> Path:
    text = "\n".join(lines) + end
    if gz:
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


def read_back(path: Path) -> dict[str, list[LaserScan | Pose2D]]:
    out: dict[str, list] = {SCAN: [], ODOM: [], TRUTH: []}
    logs: list[int] = []
    for m in McapMessages(path):
        stream = m.topic.split("/", 2)[2]
        out[stream].append(decode_laser_scan(m.data) if stream == SCAN else decode_pose(m.data))
        logs.append(m.log_time_ns)
    assert logs == sorted(logs)  # written in log-time order
    return out


def run(tmp_path: Path, lines: list[str], warned: list[str] | None = None, **kw) -> tuple[ImportResult, dict]:
    src = write_log(tmp_path / "robot.log", lines)
    res = import_log(
        src, tmp_path / "out.mcap", overwrite=True, emit=(warned.append if warned is not None else None), **kw
    )
    assert res.stats.balanced, res.stats.as_dict()
    return res, read_back(res.output)


HEADER = [
    "# CARMEN Logfile",
    "# robot: testbot",
    "PARAM robot_frontlaser_offset 0.25 1000.0 robot 1000.0",
    "PARAM laser_front_laser_type LMS 1000.0 robot 1000.0",
]


# ---- lines -------------------------------------------------------------------------------


def test_every_line_type_parses() -> None:
    line = parse_line(flaser(4, 1001.0))
    assert isinstance(line, LaserLine) and line.kind == "FLASER" and line.laser == 1
    assert line.ranges.tolist() == [1, 2, 3, 4] and line.laser_pose == (1, 2, 0.5)
    assert line.times.ipc == 1001.0 and line.times.logger == pytest.approx(1.0) and line.times.host == "robot"
    rl = parse_line(flaser(3, 1.0).replace("FLASER", "RLASER"))
    assert isinstance(rl, LaserLine) and rl.laser == 2
    o = parse_line(odom(1002.0, x=3.5))
    assert isinstance(o, OdomLine) and o.pose == (3.5, 2.0, 0.5)
    tp = parse_line(f"TRUEPOS 1 2 3 4 5 6 {times(1003.0)}")
    assert isinstance(tp, TruePosLine) and tp.true_pose == (1, 2, 3) and tp.odom_pose == (4, 5, 6)
    assert parse_line("PARAM robot_frontlaser_offset 0.25 1 h 1") == ParamLine(
        "robot_frontlaser_offset", "0.25"
    )
    for text in (robotlaser(1004.0), robotlaser(1004.0, old=True)):  # with and without remission_mode
        r = parse_line(text)
        assert isinstance(r, LaserLine) and r.geometry is not None and r.ranges.tolist() == [2, 3, 4, 5, 6]
        assert r.geometry.start_angle == pytest.approx(-math.pi / 4) and r.geometry.max_range == 81.92
        assert r.robot_pose == (1, 2, 0.5)
    raw = parse_line(rawlaser(1005.0).replace("RAWLASER1", "RAWLASER3"))
    assert isinstance(raw, LaserLine) and raw.laser == 3 and raw.laser_pose is None


def test_bad_lines_name_their_reason() -> None:
    cases = {
        "truncated_line": flaser(10, 1.0)[:40],
        "bad_line": flaser(3, 1.0).replace("2.00", "2.x0"),
        "zero_beams": "FLASER 0 1 2 3 1 2 3 1.0 h 1.0",
    }
    for reason, text in cases.items():
        with pytest.raises(LineError) as err:
            parse_line(text)
        assert err.value.reason == reason, (reason, str(err.value))
    with pytest.raises(LineError, match="fields"):
        parse_line(robotlaser(1.0) + " 7")  # one field too many fits neither layout


def test_beam_angle_conventions() -> None:
    assert beam_convention(361) == "n-1" and beam_convention(181) == "n-1"
    assert beam_convention(360) == "n" and beam_convention(180) == "n"
    assert beam_convention(361, "n") == "n"
    with pytest.raises(ValueError, match="convention"):
        beam_convention(361, "n+1")


def test_time_resolution_reads_the_printed_digits() -> None:
    assert time_resolution("1.13486e+09") == pytest.approx(1e4)
    assert time_resolution("0.227623") == pytest.approx(1e-6)
    assert time_resolution("1134864630.105179") == pytest.approx(1e-6)


# ---- the import --------------------------------------------------------------------------


def test_flaser_log_imports_scans_odometry_and_mount(tmp_path: Path) -> None:
    lines = [
        *HEADER,
        odom(1000.5),
        flaser(361, 1001.0),
        odom(1001.1, 1.1),
        flaser(360, 1001.2),
        "NEFF 10 0 h 0",
    ]
    warned: list[str] = []
    res, got = run(tmp_path, lines, warned)
    s = res.stats
    assert s.read == len(lines) and s.imported == 2
    assert s.skipped == {"comment": 2, "param": 2, "odometry_not_used": 2, "unknown_type": 1}
    assert s.unknown_types == {"NEFF": 1} and any("line 9: unknown line type 'NEFF'" in w for w in warned)
    a, b = got[SCAN]
    assert a.n_beams == 361 and a.angle_min == pytest.approx(-math.pi / 2)
    assert a.angle_increment == pytest.approx(math.pi / 360) and a.angle_max == pytest.approx(math.pi / 2)
    assert b.n_beams == 360 and b.angle_increment == pytest.approx(math.pi / 360)
    assert b.angle_max == pytest.approx(math.pi / 2 - math.pi / 360)
    assert a.stamp == pytest.approx(1001.0) and a.range_max == pytest.approx(81.82) and a.seq == 1
    # odometry from the laser lines, at the scans' stamps; log times on the ipc clock
    assert [p.stamp for p in got[ODOM]] == pytest.approx([1001.0, 1001.2])
    assert got[ODOM][0].x == pytest.approx(1.0) and got[ODOM][0].frame_id == "odom"
    logs = [m.log_time for m in McapMessages(res.output)]
    assert logs[0] == pytest.approx(1001.0)  # logger time + the median ipc - logger offset
    meta = read_recording_metadata(res.output)
    assert meta["robot"] == "robot" and meta["writer"] == "loci import" and meta["source_format"] == "carmen"
    params = PipelineParams.from_table(json.loads(meta["pipeline"]))
    assert params.mount == pytest.approx((0.25, 0.0, 0.0))


def test_forced_beam_convention_and_fov_param(tmp_path: Path) -> None:
    lines = ["PARAM laser_front_laser_fov 100 1 h 1", flaser(361, 1001.0), flaser(361, 1001.2)]
    _, got = run(tmp_path, lines, carmen=CarmenOptions(beam_angles="n"))
    scan = got[SCAN][0]
    assert scan.angle_min == pytest.approx(-math.radians(50))
    assert scan.angle_increment == pytest.approx(math.radians(100) / 361)


def test_odom_lines_as_odometry_and_laser_lines_deduplicated(tmp_path: Path) -> None:
    lines = [
        odom(1000.9, 0.9),
        rawlaser(1001.0),
        robotlaser(1001.0),
        flaser(5, 1001.0),
        odom(1001.1, 1.1),
        f"TRUEPOS 5 6 0.1 1 2 0.5 {times(1001.15)}",
    ]
    res, got = run(tmp_path, lines, carmen=CarmenOptions(odometry="odom"))
    assert res.choices["scan_lines"] == "ROBOTLASER1"
    assert res.stats.skipped == {"duplicate": 2}
    assert [p.x for p in got[ODOM]] == pytest.approx([0.9, 1.1])
    (scan,) = got[SCAN]
    assert scan.n_beams == 5 and scan.angle_min == pytest.approx(-math.pi / 4)
    assert scan.angle_increment == pytest.approx(
        math.pi / 8, abs=1e-7
    )  # fov/(n-1), not the rounded resolution
    (truth,) = got[TRUTH]
    assert (truth.x, truth.y, truth.frame_id) == (5, 6, "map")


def test_corrected_laser_pose_is_the_reference(tmp_path: Path) -> None:
    robot = (1.0, 2.0, math.pi / 2)  # the mount is 0.25 m ahead (HEADER[2])
    geometric = (1.0, 2.25, math.pi / 2)  # the robot pose moved by the mount: no news
    corrected = (3.0, 4.25, math.pi / 2)  # a SLAM tool's laser pose: the robot at (3, 4)
    lines = [
        HEADER[2],
        robotlaser(1001.0, laser_pose=geometric, robot_pose=robot),
        robotlaser(1001.1, laser_pose=corrected, robot_pose=robot),
        robotlaser(1001.2),
    ]
    _, got = run(tmp_path, lines)
    (truth,) = got[TRUTH]
    assert (truth.x, truth.y, truth.theta) == pytest.approx((3.0, 4.0, math.pi / 2))
    assert truth.stamp == pytest.approx(1001.1)
    _, got = run(tmp_path, lines, carmen=CarmenOptions(truth="laser"))
    assert len(got[TRUTH]) == 3 and got[TRUTH][2].x == pytest.approx(1.0)  # one pose per line: the robot's
    _, got = run(tmp_path, lines, carmen=CarmenOptions(truth="none"))
    assert got[TRUTH] == []


def test_sick_codes_map_as_the_driver_maps_them(tmp_path: Path) -> None:
    ranges = ["81.83", "81.91", "81.84", "81.90", "1.50", "81.82", "81.95"]
    lines = [*HEADER, flaser(7, 1001.0, ranges), flaser(7, 1001.2, ranges)]
    res, got = run(tmp_path, lines)
    r = got[SCAN][0].ranges
    rmax = got[SCAN][0].range_max
    assert rmax == pytest.approx(81.82)
    assert r[0] == r[1] == pytest.approx(rmax)  # > maximum, no echo: no return
    assert r[2] == r[3] == 0.0  # error codes: invalid
    assert r[4] == pytest.approx(1.5) and r[5] == pytest.approx(81.82) and r[6] == pytest.approx(rmax)
    assert res.stats.beams["sick_no_return"] == 4 and res.stats.beams["sick_invalid"] == 4
    _, got = run(
        tmp_path,
        [flaser(7, 1001.0, ranges), flaser(7, 1001.2, ranges)],
        carmen=CarmenOptions(sick_codes="off"),
    )
    assert got[SCAN][0].ranges[1] == pytest.approx(81.91) and got[SCAN][0].range_max == pytest.approx(81.95)
    # a Hokuyo (laser type 2) is not a SICK: its 81.91 stays
    hok = (
        robotlaser(1001.0, n=3).replace("ROBOTLASER1 0 ", "ROBOTLASER1 2 ").replace("2.00 3.00", "81.91 3.00")
    )
    _, got = run(tmp_path, [hok])
    assert got[SCAN][0].ranges[0] == pytest.approx(81.91)


def test_bad_input_is_counted_warned_and_never_stops_the_import(tmp_path: Path) -> None:
    lines = [
        flaser(5, 1001.0),
        flaser(5, 1001.2, ["1", "nan", "-2", "3", "4"]),  # kept, bad beams invalid
        "FLASER 0 1 2 3 1 2 3 1001.3 h 1.3",  # a laser with 0 beams
        "BANANA 1 2 3",  # unknown type
        flaser(5, 1001.4).replace("3.00", "x"),  # not a number
        flaser(5, 1000.5),  # logged before the line before it
        "FLASER 2 1 2 0 0 0 0 0 0 0 h 0",  # ... (times 0)
        flaser(5, 1001.6),
        flaser(5, 1001.8)[:30],  # the last line, cut in the middle
    ]
    warned: list[str] = []
    res, got = run(tmp_path, lines, warned)
    s = res.stats
    assert s.read == 9 and s.imported == 3 and len(got[SCAN]) == 3
    assert s.skipped == {
        "zero_beams": 1,
        "unknown_type": 1,
        "bad_line": 1,
        "time_backwards": 1,
        "no_time": 1,
        "truncated_line": 1,
    }
    assert s.notes == {"bad_ranges": 1}
    assert got[SCAN][1].ranges.tolist() == [1, 0, 0, 3, 4]
    text = "\n".join(warned)
    for needle in ("line 2: 2 of 5 ranges", "line 3: FLASER line with 0 beams", "line 4: unknown line type 'BANANA'",
                   "line 5: FLASER range: 'x' is not a number", "line 6: logged at", "line 7: FLASER with times 0",
                   "line 9: FLASER line has"):  # fmt: skip
        assert needle in text, (needle, text)
    with pytest.raises(DataError, match=r"line 2: 2 of 5 ranges.*--strict"):
        import_log(tmp_path / "robot.log", tmp_path / "strict.mcap", strict=True, emit=lambda s: None)
    assert not (tmp_path / "strict.mcap").exists() and not (tmp_path / "strict.mcap.partial").exists()


def test_warnings_are_rate_limited(tmp_path: Path) -> None:
    lines = [flaser(5, 1001.0)] + [f"NEFF {i} 0 h 0" for i in range(10)]
    warned: list[str] = []
    run(tmp_path, lines, warned)
    assert len([w for w in warned if "NEFF" in w]) == 3
    assert warned[-1] == "... and 7 more unknown_type warnings like these"


def test_gzip_and_a_truncated_gzip(tmp_path: Path) -> None:
    lines = [odom(1000.0 + i / 10) if i % 2 else flaser(181, 1000.0 + i / 10) for i in range(400)]
    src = write_log(tmp_path / "robot.log.gz", lines, gz=True)
    res = import_log(src, tmp_path / "a.mcap", emit=lambda s: None)
    assert res.stats.written[SCAN] == 200 and not res.stats.file_errors
    cut = tmp_path / "cut.log.gz"
    data = src.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    warned: list[str] = []
    res = import_log(cut, tmp_path / "b.mcap", emit=warned.append)
    assert res.stats.file_errors == {"truncated_file": 1} and res.stats.balanced
    assert 0 < res.stats.written[SCAN] < 200
    assert any("ends early (truncated gzip stream) after line" in w for w in warned)
    with pytest.raises(DataError, match="truncated"):
        import_log(cut, tmp_path / "c.mcap", strict=True, emit=lambda s: None)


def test_coarse_times_get_a_line_clock(tmp_path: Path) -> None:
    lines = [
        "ODOM 0 0 0 0 0 0 1.13486e+09 h 1.13486e+09",
        flaser(5, 0).replace("0.000000 robot -1000.000000", "1.13486e+09 h 1.13486e+09"),
        "ODOM 1 2 0.5 0 0 0 0 h 0",  # a corrected copy with times 0
        "ODOM 0.1 0 0 0 0 0 1.13486e+09 h 1.13486e+09",
        flaser(5, 0).replace("0.000000 robot -1000.000000", "1.13486e+09 h 1.13486e+09"),
    ]
    res, got = run(tmp_path, lines, carmen=CarmenOptions(odometry="odom"))
    assert res.choices["clock"].startswith("lines: 4 of 4 message times")
    assert [p.stamp for p in got[ODOM]] == pytest.approx([1134860000.0, 1134860000.2])
    assert [s.stamp for s in got[SCAN]] == pytest.approx([1134860000.1, 1134860000.3])
    assert res.stats.skipped == {"no_time": 1}


def test_converter_needs_a_laser() -> None:
    with pytest.raises(ValueError, match="no laser lines"):
        CarmenConverter(survey_lines([odom(1.0)]))
    with pytest.raises(ValueError, match="no lines of laser 2"):
        CarmenConverter(survey_lines([flaser(3, 1.0)]), CarmenOptions(laser=2))
    conv = CarmenConverter(survey_lines([flaser(3, 1.0), flaser(3, 1.0).replace("FLASER", "RLASER")]))
    assert conv.convert(2, flaser(3, 1.0).replace("FLASER", "RLASER")) == Skip("other_laser")


def test_odd_ranges_never_reach_the_scan_as_nan(tmp_path: Path) -> None:
    _, got = run(tmp_path, [flaser(4, 1001.0, ["inf", "-inf", "nan", "1"]), flaser(4, 1001.1)])
    r = got[SCAN][0].ranges
    assert np.all(np.isfinite(r)) and r.tolist() == [0, 0, 0, 1]


def test_every_warned_reason_is_bad_input(tmp_path: Path) -> None:
    from agent.recording.imported import BAD_INPUT

    lines = [flaser(5, 1001.0), "BANANA", flaser(5, 1001.2, ["nan", "1", "1", "1", "1"]), flaser(5, 1000.0)]
    src = write_log(tmp_path / "w.log", lines)
    res = import_log(src, tmp_path / "w.mcap", emit=lambda s: None)
    assert set(res.warnings) == {"unknown_type", "bad_ranges", "time_backwards"}
    assert set(res.warnings) <= BAD_INPUT
