"""The bag importer on bags written by the ``rosbags`` writers: ROS 1, ROS 2 sqlite3 and ROS 2
MCAP; LaserScan with a negative increment and REP 117 ranges; Odometry and /tf odometry; the
laser's mount from a static + dynamic tf chain; a message type outside rosbags' store; a
corrupt message; topics found by type, and the errors when that is ambiguous."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from support.bags import T0, Bag, write_standard_bag

from agent.bus.codecs import decode_laser_scan, decode_pose
from agent.core.pipeline import PipelineParams
from agent.recording.imported import ODOM, SCAN
from agent.recording.importer import detect_format, import_log
from agent.recording.offline import read_recording_metadata
from agent.recording.replay import McapMessages
from agent.recording.rosbag import choose_topics
from knowledge.errors import ConfigError, DataError


@pytest.mark.parametrize("version", ["ros1", "ros2-sqlite3", "ros2-mcap"])
def test_bags_of_every_kind_import(tmp_path: Path, version: str) -> None:
    path = write_standard_bag(tmp_path, version)
    assert detect_format(path) == ("ros1" if version == "ros1" else "ros2")
    warned: list[str] = []
    res = import_log(path, tmp_path / "out.mcap", emit=warned.append)
    s = res.stats
    assert s.balanced and s.read == 1 + 21 + 10 + 1 + 1
    assert s.written == {SCAN: 10, ODOM: 21}
    assert s.skipped == {"tf_used": 1, "other_topic": 1, "corrupt_message": 1}
    assert any("message 34 on /scan" in w for w in warned), warned
    assert res.choices["scan_topic"] == "/scan" and res.choices["odom_topic"] == "/odom"
    assert res.choices["base_frame"] == "base_link" and res.choices["odom_frame"] == "odom"
    # the mount: base_link → mount → laser
    assert res.mount == pytest.approx((0.2, 0.1, math.pi / 2))
    meta = read_recording_metadata(res.output)
    assert PipelineParams.from_table(json.loads(meta["pipeline"])).mount == pytest.approx(res.mount)
    assert (
        meta["source_format"]
        == {"ros1": "ros1", "ros2-sqlite3": "ros2-sqlite3", "ros2-mcap": "ros2-mcap"}[version]
    )

    msgs = list(McapMessages(res.output))
    scans = [decode_laser_scan(m.data) for m in msgs if m.topic.endswith("/scan")]
    odoms = [decode_pose(m.data) for m in msgs if m.topic.endswith("/odom")]
    first = scans[0]
    # a negative increment reversed: beams counter-clockwise from -1.0 rad
    assert first.angle_increment == pytest.approx(0.5) and first.angle_min == pytest.approx(-1.0)
    # reversed order of [1, inf, nan, 20 (> range_max), 0]: REP 117 → our convention
    assert first.ranges.tolist() == pytest.approx([0.0, 10.0, 0.0, 10.0, 1.0])
    assert first.range_max == 10.0 and first.range_min == pytest.approx(0.05) and first.frame_id == "laser"
    assert first.stamp == pytest.approx(T0 + 0.001)
    assert (
        odoms[3].x == pytest.approx(0.3)
        and odoms[3].theta == pytest.approx(0.03)
        and odoms[3].frame_id == "odom"
    )
    logs = [m.log_time_ns for m in msgs]
    assert logs == sorted(logs) and msgs[0].log_time == pytest.approx(T0 + 0.005)


def test_tf_odometry_and_a_flipped_laser(tmp_path: Path) -> None:
    path = tmp_path / "tf.bag"
    bag = Bag(path, "ros1")
    # upside down (roll 180°), facing forwards, 0.3 m ahead
    bag.tf("/tf_static", [bag.transform("base_footprint", "base_link", (0.0, 0.0, 0.1)),
                          bag.transform("base_link", "laser", (0.3, 0.0, 0.2), roll=math.pi)], T0)  # fmt: skip
    for i in range(6):
        t = T0 + 0.1 * i
        bag.tf(
            "/tf",
            [bag.transform("odom", "base_footprint", (0.5 * i, 0.0, 0.0), yaw=0.1 * i, stamp=t)],
            t + 0.002,
        )
        bag.scan(t + 0.05, [1.0, 2.0, 3.0], inc=0.5, start=-0.5)
    bag.close()
    res = import_log(path, tmp_path / "out.mcap", emit=lambda s: None)
    assert res.choices["odom_topic"] == "/tf" and res.choices["flipped"] == "true"
    assert res.mount == pytest.approx((0.3, 0.0, 0.0))
    assert res.stats.written == {SCAN: 6, ODOM: 6}
    msgs = list(McapMessages(res.output))
    odoms = [decode_pose(m.data) for m in msgs if m.topic.endswith("/odom")]
    assert odoms[2].x == pytest.approx(1.0) and odoms[2].theta == pytest.approx(0.2)
    assert odoms[2].stamp == pytest.approx(T0 + 0.2)
    scan = next(decode_laser_scan(m.data) for m in msgs if m.topic.endswith("/scan"))
    # mirrored: the beam at +0.5 rad in the upside-down laser looks at -0.5 rad about the base's z
    assert scan.ranges.tolist() == [3.0, 2.0, 1.0] and scan.angle_min == pytest.approx(-0.5)


def test_topics_found_by_type_or_named() -> None:
    topics = {
        "/front": "sensor_msgs/msg/LaserScan",
        "/rear": "sensor_msgs/msg/LaserScan",
        "/odom": "nav_msgs/msg/Odometry",
        "/odom_filtered": "nav_msgs/msg/Odometry",
        "/tf": "tf2_msgs/msg/TFMessage",
    }
    with pytest.raises(ConfigError, match=r"2 sensor_msgs/LaserScan topics \(/front, /rear\).*--scan-topic"):
        choose_topics(topics)
    with pytest.raises(
        ConfigError, match=r"2 nav_msgs/Odometry topics \(/odom, /odom_filtered\).*--odom-topic"
    ):
        choose_topics(topics, "/front")
    assert choose_topics(topics, "/front", "/odom") == ("/front", "/odom")
    assert choose_topics(topics, "/rear", "/tf") == ("/rear", "/tf")
    with pytest.raises(ConfigError, match="not in the bag; LaserScan topics: /front, /rear"):
        choose_topics(topics, "/scan")
    with pytest.raises(ConfigError, match="is nav_msgs/msg/Odometry, not sensor_msgs/msg/LaserScan"):
        choose_topics(topics, "/odom")
    assert choose_topics({"/s": "sensor_msgs/msg/LaserScan", "/tf": "tf2_msgs/msg/TFMessage"}) == (
        "/s",
        "/tf",
    )
    with pytest.raises(ConfigError, match="neither"):
        choose_topics({"/s": "sensor_msgs/msg/LaserScan"})


def test_no_mount_in_tf_is_warned_and_mount_option_wins(tmp_path: Path) -> None:
    path = tmp_path / "nomount.bag"
    bag = Bag(path, "ros1")
    for i in range(3):
        bag.odometry(T0 + 0.1 * i, x=0.1 * i, yaw=0.0)
        bag.scan(T0 + 0.1 * i + 0.01, [1.0, 2.0])
    bag.close()
    warned: list[str] = []
    res = import_log(path, tmp_path / "a.mcap", emit=warned.append)
    assert res.mount == (0.0, 0.0, 0.0) and any("do not connect base_link to laser" in w for w in warned)
    with pytest.raises(DataError, match="no_mount"):
        import_log(path, tmp_path / "b.mcap", strict=True, emit=lambda s: None)
    from agent.recording.rosbag import RosOptions

    res = import_log(path, tmp_path / "c.mcap", ros=RosOptions(mount=(0.1, 0.0, 0.5)), emit=warned.append)
    assert res.mount == (0.1, 0.0, 0.5)


def test_a_damaged_bag_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "junk.bag"
    path.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    with pytest.raises(DataError, match="cannot open as a ROS 1 bag"):
        import_log(path, tmp_path / "a.mcap")
