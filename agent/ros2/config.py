"""``[ros2]``: the optional ROS 2 interface over Zenoh (docs/ros2.md)."""

from __future__ import annotations

import re
from dataclasses import dataclass

#: The two conventions ROS 2 uses over Zenoh.
CONVENTIONS = ("rmw_zenoh", "bridge")
_NAME = re.compile(r"/?[A-Za-z_~{][A-Za-z0-9_/{}~]*")


@dataclass(frozen=True)
class Ros2Config:
    """``[ros2]`` (docs/ros2.md).

    Attributes:
        enabled: run the interface (default: on when the section is present).
        convention: ``"rmw_zenoh"`` (ROS 2 nodes with ``RMW_IMPLEMENTATION=rmw_zenoh_cpp``:
            keys ``<domain>/<topic>/<type>/<hash>``, liveliness tokens) or ``"bridge"``
            (``zenoh-bridge-ros2dds`` beside DDS nodes: key = the topic name).
        domain: ``ROS_DOMAIN_ID`` (rmw_zenoh's first key chunk).
        namespace: the ROS namespace of the topics below that are relative (no leading ``/``),
            and of the interface's node.
        node: the node name ROS 2 tools see (``ros2 node list``).
        scan, odom: the topics subscribed (``sensor_msgs/LaserScan``, ``nav_msgs/Odometry``);
            ``odom = ""``: the pose comes from ``tf`` (``odom_frame`` → ``base_frame``).
        tf, tf_static: the transform topics (the laser's mount on the base, the odometry).
        place: the topic the current place is published on (``std_msgs/String`` with the
            ``loci.place/1`` JSON).
        markers: the topic of the graph and the areas (``visualization_msgs/MarkerArray``).
        odom_frame, base_frame: frame names (REP 105).
        mode, connect, listen: the Zenoh session on the ROS 2 side (by default a client of
            the Zenoh router ``rmw_zenohd`` or ``zenoh-bridge-ros2dds`` on this machine).
    """

    enabled: bool | None = None
    convention: str = "rmw_zenoh"
    domain: int = 0
    namespace: str = ""
    node: str = "genius_loci"
    scan: str = "/scan"
    odom: str = "/odom"
    tf: str = "/tf"
    tf_static: str = "/tf_static"
    place: str = "/loci/place"
    markers: str = "/loci/markers"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    mode: str = "client"
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.convention not in CONVENTIONS:
            raise ValueError(f"convention must be one of {CONVENTIONS}, got {self.convention!r}")
        if not 0 <= self.domain <= 232:
            raise ValueError(f"domain must be a ROS_DOMAIN_ID 0..232, got {self.domain}")
        for name in ("scan", "tf", "tf_static", "place", "markers"):
            if not _NAME.fullmatch(getattr(self, name)):
                raise ValueError(f"{name} must be a ROS topic name like /scan, got {getattr(self, name)!r}")
        if self.odom and not _NAME.fullmatch(self.odom):
            raise ValueError(
                f"odom must be a ROS topic name like /odom or '' (pose from tf), got {self.odom!r}"
            )
        if self.namespace and not _NAME.fullmatch(self.namespace):
            raise ValueError(f"namespace must be like /robot1 or '', got {self.namespace!r}")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", self.node):
            raise ValueError(f"node must be a ROS node name (letters, digits, _), got {self.node!r}")
        if self.mode not in ("peer", "client"):
            raise ValueError(f"mode must be 'peer' or 'client', got {self.mode!r}")

    @property
    def on(self) -> bool:
        return bool(self.enabled)
