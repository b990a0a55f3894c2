"""Small ROS 1 and ROS 2 bags written with the rosbags writers: scans, odometry, tf, an unknown type, a corrupt message."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

T0 = 1_700_000_000.0


PERSON_DEF = "float64 x\nfloat64 y\nint32 track_id\n"  # a type no ROS distribution has


class Bag:
    """Writes a small bag with the rosbags writers."""

    def __init__(self, path: Path, version: str) -> None:
        self.version = version
        self.store = get_typestore(Stores.ROS1_NOETIC if version == "ros1" else Stores.ROS2_HUMBLE)
        self.store.register(get_types_from_msg(PERSON_DEF, "my_msgs/msg/Person"))
        if "tf2_msgs/msg/TFMessage" not in self.store.types:  # rosbags' ROS 1 store lacks it
            self.store.register(
                get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
            )
        if version == "ros1":
            self.writer: Any = Writer1(path)
        else:
            plugin = StoragePlugin.MCAP if version == "ros2-mcap" else StoragePlugin.SQLITE3
            self.writer = Writer2(path, version=9, storage_plugin=plugin)
        self.writer.open()
        self.conns: dict[str, Any] = {}
        self.t = self.store.types

    def close(self) -> None:
        self.writer.close()

    def header(self, stamp: float, frame: str) -> Any:
        sec = math.floor(stamp)
        time = self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
        if self.version == "ros1":
            return self.t["std_msgs/msg/Header"](seq=0, stamp=time, frame_id=frame)
        return self.t["std_msgs/msg/Header"](stamp=time, frame_id=frame)

    def write(self, topic: str, msgtype: str, msg: Any, log_time: float, raw: bytes | None = None) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=self.store)
        if raw is None:
            ser = self.store.serialize_ros1 if self.version == "ros1" else self.store.serialize_cdr
            raw = bytes(ser(msg, msgtype))
        self.writer.write(self.conns[topic], round(log_time * 1e9), raw)

    def scan(
        self,
        stamp: float,
        ranges: list[float],
        *,
        inc: float = 0.5,
        start: float = -1.0,
        topic: str = "/scan",
        frame: str = "laser",
    ) -> None:
        msg = self.t["sensor_msgs/msg/LaserScan"](
            header=self.header(stamp, frame),
            angle_min=start,
            angle_max=start + (len(ranges) - 1) * inc,
            angle_increment=inc,
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.05,
            range_max=10.0,
            ranges=np.array(ranges, dtype=np.float32),
            intensities=np.array([], dtype=np.float32),
        )
        self.write(topic, "sensor_msgs/msg/LaserScan", msg, stamp + 0.01)

    def transform(
        self,
        parent: str,
        child: str,
        xyz: tuple[float, float, float],
        yaw: float = 0.0,
        roll: float = 0.0,
        stamp: float = T0,
    ) -> Any:
        # rotation about z by yaw, then about x by roll: q = qz * qx
        cz, sz, cx, sx = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
        q = self.t["geometry_msgs/msg/Quaternion"](x=cz * sx, y=sz * sx, z=sz * cx, w=cz * cx)
        v = self.t["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2])
        return self.t["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp, parent),
            child_frame_id=child,
            transform=self.t["geometry_msgs/msg/Transform"](translation=v, rotation=q),
        )

    def tf(self, topic: str, transforms: list[Any], log_time: float) -> None:
        self.write(
            topic, "tf2_msgs/msg/TFMessage", self.t["tf2_msgs/msg/TFMessage"](transforms=transforms), log_time
        )

    def odometry(self, stamp: float, x: float, yaw: float, topic: str = "/odom") -> None:
        t = self.t
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=0.5, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
            ),
        )
        twist = t["geometry_msgs/msg/Twist"](
            linear=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        )
        msg = t["nav_msgs/msg/Odometry"](
            header=self.header(stamp, "/odom"),
            child_frame_id="/base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )
        self.write(topic, "nav_msgs/msg/Odometry", msg, stamp + 0.005)

    def person(self, stamp: float) -> None:
        msg = self.t["my_msgs/msg/Person"](x=1.0, y=2.0, track_id=7)
        self.write("/people", "my_msgs/msg/Person", msg, stamp)


def bag_path(tmp_path: Path, version: str) -> Path:
    return tmp_path / {"ros1": "run.bag", "ros2-sqlite3": "run_db3", "ros2-mcap": "run_mcap"}[version]


def write_standard_bag(tmp_path: Path, version: str) -> Path:
    """10 scans (negative increment, REP 117 ranges), 21 odometry messages, a static tf chain
    base_link → mount (0.2, 0, 0, yaw 90°) → laser (0.1, 0, 0), a person topic, one corrupt scan."""
    path = bag_path(tmp_path, version)
    bag = Bag(path, version)
    bag.tf("/tf_static", [bag.transform("base_link", "mount", (0.2, 0.0, 0.3), yaw=math.pi / 2),
                          bag.transform("mount", "laser", (0.1, 0.0, 0.0))], T0)  # fmt: skip
    for i in range(21):
        bag.odometry(T0 + 0.05 * i, x=0.1 * i, yaw=0.01 * i)
        if i % 2 == 0 and i < 20:
            bag.scan(T0 + 0.05 * i + 0.001, [1.0, math.inf, math.nan, 20.0, 0.0], inc=-0.5, start=1.0)
        if i == 7:
            bag.person(T0 + 0.05 * i)
    bag.write("/scan", "sensor_msgs/msg/LaserScan", None, T0 + 2.0, raw=b"\x00\x01\x02")
    bag.close()
    return path
