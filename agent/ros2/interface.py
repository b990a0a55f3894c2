"""The ROS 2 interface: a bridge between a ROS 2 Zenoh network and the agent's bus (``[ros2]``).

It opens its own Zenoh session on the ROS 2 side (by default a client of the Zenoh router on
this machine: ``rmw_zenohd``, or ``zenoh-bridge-ros2dds``), and on the agent's session:

==========================  ============================  =====================================
ROS 2 (CDR)                 agent (``loci/<robot>/…``)     what
==========================  ============================  =====================================
``scan`` LaserScan      →   ``scan`` (foxglove.LaserScan)  REP 117 ranges, clockwise beams
                                                           reversed, an upside-down laser mirrored
``odom`` Odometry       →   ``odom`` (PoseInFrame)         the base's pose in the odometry frame
(``odom = ""``) ``/tf`` →   ``odom``                       ``odom_frame → base_frame`` from tf
``/tf``, ``/tf_static`` →   —                              the laser's mount on the base, checked
                                                           against ``[laser.mount]``
``place`` String        ←   ``place`` (loci.place/1)       the JSON of every place message
``markers`` MarkerArray ←   ``graph`` + ``areas``           when either changes
==========================  ============================  =====================================

The scans and poses are published on the agent's keys, so the agent (``laser.source =
"bus"``), a recording and ``loci replay`` see them exactly as from any other driver. Keys
and liveliness tokens follow :mod:`agent.ros2.names`; with ``convention = "rmw_zenoh"`` the
interface declares a node and one token per publisher and subscription, so ``ros2 node
list`` and ``ros2 topic list`` on a ROS 2 machine show it, and each published sample
carries rmw_zenoh's attachment. CDR bytes that are not the expected message are counted
(``invalid`` of ``ros2/<topic>``) and dropped, as any bad sample on the bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import zenoh

from agent.bus.bridge import BusClosed, BusStats, Subscription, publish_stream, subscribe_stream
from agent.bus.keys import Policy
from agent.bus.session import BusConfig, close_session, open_session
from agent.recording.rosbag import BadMessage, TfBuffer, frame, pose_from_odometry, scan_from_ros
from agent.ros2 import messages as rm
from agent.ros2 import names
from agent.ros2.config import Ros2Config
from knowledge.errors import ProtocolError

log = logging.getLogger(__name__)

#: Samples each ROS 2 subscription keeps for a busy loop (drop-oldest beyond, counted).
QUEUE = 256


class Ros2Interface:
    """The bridge (see the module docstring).

    Args:
        config: ``[ros2]``.
        loci_session: the agent's Zenoh session.
        robot: the agent's robot name.
        mount: ``[laser.mount]`` as ``(x, y, yaw)`` (checked against the tf tree).
        stats: counters (the agent's, so its diagnostics show ``ros2/...`` streams).
        ros_session: a session on the ROS 2 side to use instead of opening one (not closed here).
    """

    def __init__(
        self,
        config: Ros2Config,
        loci_session: zenoh.Session,
        robot: str,
        *,
        mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
        stats: BusStats | None = None,
        ros_session: zenoh.Session | None = None,
    ) -> None:
        self.config = config
        self.robot = robot
        self.mount = mount
        self.stats = stats or BusStats()
        self._loci = loci_session
        self._ros = ros_session
        self._own_session = ros_session is None
        self.tf = TfBuffer()
        self.flipped = False
        self.mount_seen: tuple[float, float, float] | None = None
        self.counts = {"scans": 0, "odometry": 0, "tf": 0, "place": 0, "markers": 0, "bad": 0}
        self._tokens: list[Any] = []
        self._subs: list[Subscription[Any]] = []
        self._closed = False
        self._static_sub: Any = None
        self._graph: dict[str, Any] | None = None
        self._areas: dict[str, Any] | None = None
        self.ready = asyncio.Event()

    # ------------------------------------------------------------------ names
    def topic(self, name: str) -> str:
        """The fully qualified name of one of the configured topics."""
        return names.qualified(name, self.config.namespace)

    def key(self, name: str, ros_type: str) -> str:
        """The Zenoh key of a configured topic in the configured convention."""
        fq = self.topic(name)
        if self.config.convention == "rmw_zenoh":
            return names.rmw_zenoh_key(self.config.domain, fq, ros_type, rm.type_hash(ros_type))
        return names.bridge_key(fq)

    def endpoints(self) -> dict[str, tuple[str, str, str]]:
        """role → ``(topic, ROS type, kind)`` of every publisher (MP) and subscription (MS)."""
        c = self.config
        out = {
            "scan": (c.scan, rm.LASER_SCAN, names.SUBSCRIPTION),
            "tf": (c.tf, rm.TF_MESSAGE, names.SUBSCRIPTION),
            "tf_static": (c.tf_static, rm.TF_MESSAGE, names.SUBSCRIPTION),
            "place": (c.place, rm.STRING, names.PUBLISHER),
            "markers": (c.markers, rm.MARKER_ARRAY, names.PUBLISHER),
        }
        if c.odom:
            out["odom"] = (c.odom, rm.ODOMETRY, names.SUBSCRIPTION)
        return out

    def tokens(self, session_id: str) -> list[str]:
        """The liveliness tokens of the node and its entities (rmw_zenoh)."""
        c = self.config
        ns = c.namespace or "/"
        out = [names.node_token(c.domain, session_id, 0, c.node, ns)]
        for i, (topic, ros_type, kind) in enumerate(self.endpoints().values(), start=1):
            out.append(
                names.entity_token(
                    c.domain, session_id, 0, i, kind, c.node, self.topic(topic), ros_type, rm.type_hash(ros_type),
                    namespace=ns,
                )
            )  # fmt: skip
        return out

    # ------------------------------------------------------------------ run
    async def run(self) -> None:
        """Bridge until cancelled (closes what it opened)."""
        c = self.config
        if self._ros is None:
            self._ros = open_session(BusConfig(mode=c.mode, listen=tuple(c.listen), connect=tuple(c.connect)))
        ros = self._ros
        try:
            if c.convention == "rmw_zenoh":
                sid = str(ros.zid())
                self._tokens = [ros.liveliness().declare_token(t) for t in self.tokens(sid)]
            gids = {
                role: hashlib.sha256(f"{self.key(t, ty)}:{role}".encode()).digest()[:16]
                for role, (t, ty, _) in self.endpoints().items()
            }
            scan_pub = publish_stream(self._loci, self.robot, "scan", stats=self.stats)
            odom_pub = publish_stream(self._loci, self.robot, "odom", stats=self.stats)
            place_out = _RosPublisher(
                ros, self.key(c.place, rm.STRING), gids["place"], c.convention == "rmw_zenoh"
            )
            markers_out = _RosPublisher(
                ros, self.key(c.markers, rm.MARKER_ARRAY), gids["markers"], c.convention == "rmw_zenoh"
            )
            scans = self._subscribe(ros, "scan", rm.LASER_SCAN)
            tf = self._subscribe(ros, "tf", rm.TF_MESSAGE)
            tf_static = self._static_subscription(ros)
            odom = self._subscribe(ros, "odom", rm.ODOMETRY) if c.odom else None
            place = subscribe_stream(self._loci, self.robot, "place", stats=self.stats, capacity=64)
            graph = subscribe_stream(self._loci, self.robot, "graph", stats=self.stats, capacity=8)
            areas = subscribe_stream(self._loci, self.robot, "areas", stats=self.stats, capacity=8)
            self._subs += [place, graph, areas]
            log.info(
                "ROS 2 interface (%s, domain %d, node %s): %s → loci/%s/scan",
                c.convention, c.domain, c.node, self.key(c.scan, rm.LASER_SCAN), self.robot,
            )  # fmt: skip
            self.ready.set()
            tasks = [
                self._pump(scans, lambda m: self._on_scan(m, scan_pub)),
                self._pump(tf, lambda m: self._on_tf(m, odom_pub)),
                self._drain(tf_static, lambda m: self._on_tf(m, None)),
                self._pump(place, lambda m: self._on_place(m, place_out)),
                self._pump(graph, lambda m: self._on_graph(m, None, markers_out)),
                self._pump(areas, lambda m: self._on_graph(None, m, markers_out)),
            ]
            if odom is not None:
                tasks.append(self._pump(odom, lambda m: self._on_odom(m, odom_pub)))
            try:
                await asyncio.gather(*tasks)
            finally:
                for pub in (scan_pub, odom_pub):
                    pub.close()
                place_out.close()
                markers_out.close()
        finally:
            self.close()

    def _subscribe(self, session: zenoh.Session, role: str, ros_type: str) -> Subscription[Any]:
        topic = getattr(self.config, role)
        sub: Subscription[Any] = Subscription(
            session,
            self.key(topic, ros_type),
            lambda raw: rm.decode(raw.payload, ros_type),
            policy=Policy.DROP_OLDEST,
            capacity=QUEUE,
            stats=self.stats,
            name=f"ros2{self.topic(topic)}",
        )
        self._subs.append(sub)
        return sub

    def _static_subscription(self, session: zenoh.Session) -> asyncio.Queue[Any]:
        """``/tf_static`` is transient local: ROS 2 keeps the last transforms for late subscribers
        (rmw_zenoh: an advanced publisher with a cache). An advanced subscriber with history asks
        for them, so the mount is known even when the robot started first."""
        from zenoh.ext import HistoryConfig, declare_advanced_subscriber

        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[Any] = asyncio.Queue(maxsize=QUEUE)
        name = f"ros2{self.topic(self.config.tf_static)}"
        counters = self.stats.stream(name)

        def put(msg: Any) -> None:
            if queue.full():
                counters.add("dropped")
                return
            queue.put_nowait(msg)
            counters.add("delivered")

        def on_sample(sample: zenoh.Sample) -> None:  # Zenoh's thread
            counters.add("received")
            try:
                msg = rm.decode(sample.payload.to_bytes(), rm.TF_MESSAGE)
            except ProtocolError as exc:
                counters.add("invalid")
                log.debug("%s: %s", name, exc)
                return
            with contextlib.suppress(RuntimeError):  # the loop closed
                loop.call_soon_threadsafe(put, msg)

        self._static_sub = declare_advanced_subscriber(
            session,
            self.key(self.config.tf_static, rm.TF_MESSAGE),
            on_sample,
            history=HistoryConfig(detect_late_publishers=True),
        )
        return queue

    async def _drain(self, queue: asyncio.Queue[Any], handle: Callable[[Any], None]) -> None:
        while True:
            msg = await queue.get()
            try:
                handle(msg)
            except (BadMessage, ProtocolError, ValueError) as exc:
                self.counts["bad"] += 1
                log.warning("ROS 2 interface: a transform was dropped: %s", exc)

    async def _pump(self, sub: Subscription[Any], handle: Callable[[Any], None]) -> None:
        with contextlib.suppress(BusClosed):
            while True:
                for item in await sub.recv_batch(QUEUE):
                    try:
                        handle(item)
                    except (BadMessage, ProtocolError, ValueError) as exc:
                        self.counts["bad"] += 1
                        if self.counts["bad"] <= 5:
                            log.warning("ROS 2 interface: a message was dropped: %s", exc)

    # ------------------------------------------------------------------ ROS → agent
    def _on_scan(self, msg: Any, pub: Any) -> None:
        scan = scan_from_ros(msg, self.counts["scans"], flipped=self.flipped)
        pub.put(scan)
        self.counts["scans"] += 1
        if self.mount_seen is None:
            self._check_mount(frame(msg.header.frame_id))

    def _on_odom(self, msg: Any, pub: Any) -> None:
        pub.put(pose_from_odometry(msg))
        self.counts["odometry"] += 1

    def _on_tf(self, msg: Any, odom_pub: Any) -> None:
        links = self.tf.add(msg)
        self.counts["tf"] += 1
        c = self.config
        if odom_pub is not None and not c.odom:
            for _parent, child, stamp in links:
                if self.tf.path(c.odom_frame, child) and self.tf.path(child, c.base_frame) is not None:
                    pose = self.tf.pose2d(c.odom_frame, c.base_frame, stamp)
                    if pose is not None:
                        odom_pub.put(pose)
                        self.counts["odometry"] += 1
                    break

    def _check_mount(self, laser_frame: str) -> None:
        """Once the tf tree joins the base and the laser: say if ``[laser.mount]`` disagrees."""
        m = self.tf.mount(self.config.base_frame, laser_frame)
        if m is None:
            return
        self.mount_seen = m.pose
        self.flipped = m.flipped
        x, y, yaw = m.pose
        mx, my, myaw = self.mount
        if math.hypot(x - mx, y - my) > 0.01 or abs(math.remainder(yaw - myaw, 2 * math.pi)) > math.radians(
            1
        ):
            log.warning(
                "ROS 2 tf puts %s at x %.3f m, y %.3f m, yaw %.1f° on %s, but [laser.mount] says x %.3f, y %.3f, "
                "yaw %.1f°: set [laser.mount] x = %.3f, y = %.3f, yaw = %.1f (every position is the laser's)",
                laser_frame, x, y, math.degrees(yaw), self.config.base_frame, mx, my, math.degrees(myaw),
                x, y, math.degrees(yaw),
            )  # fmt: skip

    # ------------------------------------------------------------------ agent → ROS
    def _on_place(self, place: dict[str, Any], out: _RosPublisher) -> None:
        out.put(rm.place_string(place))
        self.counts["place"] += 1

    def _on_graph(
        self, graph: dict[str, Any] | None, areas: dict[str, Any] | None, out: _RosPublisher
    ) -> None:
        if graph is not None:
            self._graph = graph
        if areas is not None:
            self._areas = areas
        if self._graph is None:
            return
        areas_msg = self._areas or {"areas": []}
        stamp = float(self._graph.get("stamp") or time.time())
        out.put(
            rm.graph_markers(
                self._graph, areas_msg, stamp=stamp, frame_id=self._graph.get("frame_id") or "odom"
            )
        )
        self.counts["markers"] += 1

    def close(self) -> None:
        """Undeclare the tokens and subscriptions, close the ROS 2 session if it is ours (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for sub in self._subs:
            sub.close()
        if self._static_sub is not None:
            with contextlib.suppress(Exception):
                self._static_sub.undeclare()
        for token in self._tokens:
            with contextlib.suppress(Exception):
                token.undeclare()
        if self._own_session and self._ros is not None:
            close_session(self._ros)
        self._ros = None


class _RosPublisher:
    """A Zenoh publisher of CDR samples on a ROS 2 key (with rmw_zenoh's attachment when asked)."""

    def __init__(self, session: zenoh.Session, key: str, gid: bytes, attach: bool) -> None:
        self.key = key
        self._pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
        self._gid = gid
        self._attach = attach
        self._seq = 0

    def put(self, payload: bytes) -> None:
        self._seq += 1
        attachment = rm.attachment(self._seq, time.time_ns(), self._gid) if self._attach else None
        self._pub.put(payload, attachment=attachment)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._pub.undeclare()
