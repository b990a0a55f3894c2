"""The ROS 2 interface over Zenoh: names against ROS 2's documented values, CDR from ``rosbags``,
and on the wire: real Zenoh sessions on loopback carrying CDR made from the real scans of
``../shared/data/people/general_tracking_moving_1.bag.zip``.

What this cannot show here (no ROS 2 install): that a ROS 2 node takes our samples and that
``ros2 node list`` lists us. The keys, hashes and tokens are checked against the values ROS 2's
own documentation and generated code give; docs/ros2.md says what needs a ROS 2 machine.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh

from agent.bus.bridge import BusStats, publish_stream, subscribe_stream
from agent.bus.schemas import SCHEMAS
from agent.bus.session import BusConfig, bus_session, listening_endpoints
from agent.bus.testing import session_pair, settle
from agent.ros2 import messages as rm
from agent.ros2 import names
from agent.ros2.config import Ros2Config
from agent.ros2.interface import Ros2Interface
from knowledge.errors import ConfigError, ProtocolError

# -------------------------------------------------------------------------- names and hashes

# rmw_zenoh's design notes ("Topic and Service name mapping", "Graph Cache") give these.
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
DOC_TALKER = (
    "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
)
DOC_LISTENER_NODE = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
# the hashes rosidl generates for Jazzy, as they appear in generated type support code
LASER_SCAN_HASH = "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"


def test_keys_and_tokens_match_rmw_zenohs_documented_examples() -> None:
    assert names.rmw_zenoh_key(0, "/chatter", rm.STRING, STRING_HASH) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert names.rmw_zenoh_key(0, names.qualified("chatter", "/robot1"), rm.STRING, STRING_HASH) == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert names.node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "listener") == DOC_LISTENER_NODE
    token = names.entity_token(
        2, "8b20917502ee955ac4476e0266340d5c", 0, 10, names.PUBLISHER, "talker", "/chatter", rm.STRING,
        STRING_HASH, qos="::,7:,:,:,,",
    )  # fmt: skip
    assert token == DOC_TALKER
    assert (
        names.bridge_key("/scan") == "scan"
        and names.bridge_key("/robot1/odom", "/fleet") == "fleet/robot1/odom"
    )
    assert (
        names.dds_type_name("visualization_msgs/msg/MarkerArray")
        == "visualization_msgs::msg::dds_::MarkerArray_"
    )
    with pytest.raises(ValueError, match="sensor_msgs/msg/LaserScan"):
        names.dds_type_name("LaserScan")


def test_type_hashes_from_rosbags_are_ros_2s() -> None:
    assert rm.type_hash(rm.STRING) == STRING_HASH
    assert rm.type_hash(rm.LASER_SCAN) == LASER_SCAN_HASH
    for t in (rm.ODOMETRY, rm.TF_MESSAGE, rm.MARKER_ARRAY):
        assert rm.type_hash(t).startswith("RIHS01_") and len(rm.type_hash(t)) == 7 + 64


def test_config_section() -> None:
    from agent.config import load_config

    c = load_config(table={"ros2": {"convention": "bridge", "namespace": "/tb3", "odom": ""}}, env={})
    assert c.ros2.on and c.ros2.convention == "bridge" and c.ros2.odom == ""
    assert not load_config(table={}, env={}).ros2.on
    assert not load_config(table={"ros2": {"enabled": False}}, env={}).ros2.on
    with pytest.raises(ConfigError, match="convention"):
        load_config(table={"ros2": {"convention": "dds"}}, env={})
    with pytest.raises(ConfigError, match="scan"):
        load_config(table={"ros2": {"scan": "not a topic"}}, env={})


def test_cdr_that_is_not_the_message_is_a_protocol_error() -> None:
    good = rm.place_string({"label": "room"})
    assert json.loads(rm.decode(good, rm.STRING).data) == {"label": "room"}
    for bad in (b"", b"\x00\x01\x00\x00\xff", b"{}", good[:6]):
        with pytest.raises(ProtocolError, match=r"std_msgs/msg/String|not CDR"):
            rm.decode(bad, rm.STRING)


def test_markers_of_a_graph() -> None:
    graph = {
        "stamp": 5.0,
        "nodes": [
            {"id": 0, "x": 0.0, "y": 0.0, "kind": "place", "label": "room"},
            {"id": 1, "x": 2.0, "y": 0.0, "kind": "doorway", "label": None},
            {"id": 2, "x": 4.0, "y": 1.0, "kind": "place", "label": "corridor"},
        ],
        "edges": [[0, 1], [1, 2]],
    }
    areas = {
        "areas": [{"id": 3, "label": "room", "nodes": [0]}, {"id": 4, "label": "corridor", "nodes": [2]}]
    }
    msg = rm.decode(rm.graph_markers(graph, areas, stamp=5.0, names={3: ["kitchen"]}), rm.MARKER_ARRAY)
    kinds = [(m.ns, m.type, m.action) for m in msg.markers]
    assert kinds[0] == ("loci", 0, 3)  # DELETEALL first
    nodes = msg.markers[1]
    assert nodes.type == 7 and [(p.x, p.y) for p in nodes.points] == [(0, 0), (2, 0), (4, 1)]
    assert len(nodes.colors) == 3 and nodes.header.frame_id == "odom" and nodes.header.stamp.sec == 5
    edges = msg.markers[2]
    assert edges.type == 5 and [(p.x, p.y) for p in edges.points] == [(0, 0), (2, 0), (2, 0), (4, 1)]
    texts = [m.text for m in msg.markers if m.type == 9]
    assert texts == ["room #3\nkitchen", "corridor #4"]


def test_attachment_layout() -> None:
    gid = bytes(range(16))
    data = rm.attachment(7, 123456789, gid)
    assert data == (7).to_bytes(8, "little") + (123456789).to_bytes(8, "little") + gid


# -------------------------------------------------------------------------- the real bag


def _bag(shared_data: Path, tmp: Path) -> Path:
    with zipfile.ZipFile(shared_data / "people" / "general_tracking_moving_1.bag.zip") as z:
        z.extractall(tmp)
    (bag,) = tmp.glob("**/*.bag")
    return bag


def _time(stamp: float) -> Any:
    return rm.time_msg(stamp)


def ros2_cdr(topic: str, msg: Any, shift: float) -> tuple[str, bytes]:
    """A ROS 1 message of the bag as ROS 2 CDR (stamps moved by ``shift`` seconds)."""

    def hdr(h: Any) -> Any:
        return rm.header(h.stamp.sec + h.stamp.nanosec * 1e-9 + shift, h.frame_id.lstrip("/"))

    if topic == "/scan":
        out = rm.make(
            rm.LASER_SCAN, header=hdr(msg.header), angle_min=msg.angle_min, angle_max=msg.angle_max,
            angle_increment=msg.angle_increment, time_increment=msg.time_increment, scan_time=msg.scan_time,
            range_min=msg.range_min, range_max=msg.range_max, ranges=np.asarray(msg.ranges, np.float32),
            intensities=np.asarray(msg.intensities, np.float32),
        )  # fmt: skip
        return rm.LASER_SCAN, rm.encode(out)
    if topic == "/odom":
        p = msg.pose.pose
        pose = rm.make(
            "geometry_msgs/msg/PoseWithCovariance",
            pose=rm.make(
                "geometry_msgs/msg/Pose",
                position=rm.make("geometry_msgs/msg/Point", x=p.position.x, y=p.position.y, z=p.position.z),
                orientation=rm.make(
                    "geometry_msgs/msg/Quaternion", x=p.orientation.x, y=p.orientation.y, z=p.orientation.z,
                    w=p.orientation.w,
                ),
            ),
        )  # fmt: skip
        out = rm.make(rm.ODOMETRY, header=hdr(msg.header), child_frame_id=msg.child_frame_id, pose=pose)
        return rm.ODOMETRY, rm.encode(out)
    transforms = []
    for t in msg.transforms:
        tr, q = t.transform.translation, t.transform.rotation
        transforms.append(
            rm.make(
                "geometry_msgs/msg/TransformStamped", header=hdr(t.header), child_frame_id=t.child_frame_id.lstrip("/"),
                transform=rm.make(
                    "geometry_msgs/msg/Transform",
                    translation=rm.make("geometry_msgs/msg/Vector3", x=tr.x, y=tr.y, z=tr.z),
                    rotation=rm.make("geometry_msgs/msg/Quaternion", x=q.x, y=q.y, z=q.z, w=q.w),
                ),
            )
        )  # fmt: skip
    return rm.TF_MESSAGE, rm.encode(rm.make(rm.TF_MESSAGE, transforms=transforms))


def read_bag(bag: Path, seconds: float) -> list[tuple[float, str, Any]]:
    """``(bag time, topic, ROS 1 message)`` of /scan, /odom and /tf over the first ``seconds`` of scans."""
    from rosbags.highlevel import AnyReader

    out: list[tuple[float, str, Any]] = []
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/scan", "/odom", "/tf")]
        start = None
        for conn, t, raw in reader.messages(connections=conns):
            if start is None and conn.topic == "/scan":
                start = t
            if start is None:
                out.append((t * 1e-9, conn.topic, reader.deserialize(raw, conn.msgtype)))
                continue
            if (t - start) * 1e-9 > seconds:
                break
            out.append((t * 1e-9, conn.topic, reader.deserialize(raw, conn.msgtype)))
    return out


class RosSide:
    """A Zenoh session standing in for the ROS 2 graph: publishes CDR, records what comes back."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.got: dict[str, list[tuple[bytes, bytes | None]]] = {}
        self.lock = threading.Lock()
        self._subs: list[Any] = []

    def listen(self, key: str) -> None:
        def on(sample: zenoh.Sample) -> None:
            att = sample.attachment.to_bytes() if sample.attachment is not None else None
            with self.lock:
                self.got.setdefault(key, []).append((sample.payload.to_bytes(), att))

        self._subs.append(self.session.declare_subscriber(key, on))

    def received(self, key: str) -> list[tuple[bytes, bytes | None]]:
        with self.lock:
            return list(self.got.get(key, ()))


def play(
    ros: zenoh.Session, iface: Ros2Interface, messages: list[tuple[float, str, Any]], speed: float
) -> int:
    """Publish the bag's messages as ROS 2 CDR on the interface's keys, at ``speed`` × bag time,
    stamps moved to now; returns the scans published."""
    shift = time.time() + 0.05 - messages[0][0]
    pubs: dict[str, Any] = {}
    t0, w0 = messages[0][0], time.monotonic()
    scans = 0
    for t, topic, msg in messages:
        ros_type, data = ros2_cdr(topic, msg, shift)
        role = {"/scan": "scan", "/odom": "odom", "/tf": "tf"}[topic]
        key = iface.key(getattr(iface.config, role), ros_type)
        if key not in pubs:
            pubs[key] = ros.declare_publisher(key)
        delay = (t - t0) / speed - (time.monotonic() - w0)
        if delay > 0:
            time.sleep(delay)
        pubs[key].put(data)
        scans += topic == "/scan"
    for p in pubs.values():
        p.undeclare()
    return scans


@pytest.mark.data
@pytest.mark.slow
def test_agent_classifies_real_scans_arriving_as_ros_2_cdr_over_rmw_zenoh(
    shared_data: Path, tmp_path: Path
) -> None:
    """The whole agent with ``[ros2]``: the bag's scans, odometry and tf as ROS 2 CDR on rmw_zenoh
    keys from another session; the places and markers come back as CDR on rmw_zenoh keys."""
    from agent.config import load_config
    from agent.runtime import Agent

    messages = read_bag(_bag(shared_data, tmp_path), seconds=6.0)
    with bus_session(BusConfig(listen=("tcp/127.0.0.1:0",))) as ros:
        (ros_endpoint,) = listening_endpoints(ros)
        config = load_config(
            table={
                "robot": {"name": "tb3"},
                "bus": {"listen": ["tcp/127.0.0.1:0"]},
                "state": {"dir": str(tmp_path / "state")},
                "ros2": {"mode": "peer", "connect": [ros_endpoint]},
            },
            env={},
        )
        side = RosSide(ros)
        result: dict[str, Any] = {}

        async def main() -> None:
            stop = asyncio.Event()
            agent = Agent(config)
            task = asyncio.create_task(agent.run(stop))
            while agent._ros2 is None or not agent._ros2.ready.is_set():
                await asyncio.sleep(0.05)
                assert not task.done(), task.exception()
            iface: Ros2Interface = agent._ros2
            place_key = iface.key(iface.config.place, rm.STRING)
            markers_key = iface.key(iface.config.markers, rm.MARKER_ARRAY)
            side.listen(place_key)
            side.listen(markers_key)
            await asyncio.sleep(1.0)  # declarations reach the other session
            tokens = await asyncio.to_thread(
                lambda: [
                    str(r.ok.key_expr) for r in ros.liveliness().get("@ros2_lv/0/**", timeout=2.0) if r.ok
                ]
            )
            result["scans"] = await asyncio.to_thread(play, ros, iface, messages, 1.0)
            await asyncio.sleep(1.0)
            result.update(
                tokens=tokens, place_key=place_key, markers_key=markers_key, counts=dict(iface.counts)
            )
            result["mount"] = iface.mount_seen
            stop.set()
            result["report"] = await task

        asyncio.run(main())
    report = result["report"]
    published = result["scans"]
    assert published > 40
    # every scan crossed: decoded from CDR, published on loci/tb3/scan, processed by the agent
    assert result["counts"]["scans"] == published and result["counts"]["bad"] == 0
    assert report.scans_processed >= 0.9 * published, report.as_dict()
    # the laser's mount on the base came through /tf (left_laser on base_link)
    assert result["mount"] is not None
    # the places came back as std_msgs/String CDR with rmw_zenoh's attachment
    places = side.received(result["place_key"])
    assert len(places) >= 0.9 * report.scans_processed
    first = SCHEMAS.decode(rm.decode(places[0][0], rm.STRING).data.encode(), "loci.place/1")
    assert first["label"] in ("room", "corridor", "doorway", "hallway")
    seqs = [int.from_bytes(att[:8], "little") for _, att in places if att is not None]
    assert len(seqs) == len(places) and seqs == sorted(seqs)
    markers = side.received(result["markers_key"])
    assert markers and rm.decode(markers[-1][0], rm.MARKER_ARRAY).markers[0].action == 3
    # ROS 2 tools would see the node and its publishers and subscriptions
    tokens = result["tokens"]
    assert any(t.endswith("/NN/%/%/genius_loci") for t in tokens), tokens
    assert any(
        f"/MS/%/%/genius_loci/%scan/sensor_msgs::msg::dds_::LaserScan_/{LASER_SCAN_HASH}/" in t
        for t in tokens
    )
    assert any(
        f"/MP/%/%/genius_loci/%loci%place/std_msgs::msg::dds_::String_/{STRING_HASH}/" in t for t in tokens
    )


@pytest.mark.data
def test_bridge_convention_carries_real_scans_both_ways(shared_data: Path, tmp_path: Path) -> None:
    """zenoh-bridge-ros2dds keys (the topic name): the bag's CDR scans arrive on loci/<r>/scan
    with the bag's ranges; a place published by the agent goes out on ``loci/place``."""
    messages = read_bag(_bag(shared_data, tmp_path), seconds=1.0)
    scans_in = [m for m in messages if m[1] == "/scan"]
    cfg = Ros2Config(enabled=True, convention="bridge")
    with session_pair() as (loci, ros):
        stats = BusStats()
        iface = Ros2Interface(cfg, loci, "tb3", stats=stats, ros_session=ros)
        side = RosSide(ros)
        side.listen("loci/place")
        place_msg = {
            "schema": "loci.place/1", "stamp": 1.0, "label": "corridor",
            "probabilities": {"room": 0.2, "corridor": 0.7, "doorway": 0.1},
        }  # fmt: skip

        async def main() -> list[Any]:
            got = subscribe_stream(loci, "tb3", "scan", capacity=64)
            place_pub = publish_stream(loci, "tb3", "place")
            task = asyncio.create_task(iface.run())
            await asyncio.wait_for(iface.ready.wait(), 10)
            settle(ros, loci)
            settle(loci, ros)
            pub = ros.declare_publisher("scan")
            shift = time.time() - scans_in[0][0]
            for _, topic, msg in scans_in:
                pub.put(ros2_cdr(topic, msg, shift)[1])
            pub.put(b"\x00\x01\x00\x00garbage")
            place_pub.put(place_msg)
            received = []
            while len(received) < len(scans_in):
                received += await asyncio.wait_for(got.recv_batch(64), 5)
            await asyncio.sleep(0.5)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            got.close()
            place_pub.close()
            return received

        received = asyncio.run(main())
    assert len(received) == len(scans_in)
    for scan, (_, _, msg) in zip(received, scans_in, strict=True):
        want = np.asarray(msg.ranges, np.float64)
        finite = np.isfinite(want) & (want <= msg.range_max)
        assert np.allclose(scan.ranges[finite], want[finite], atol=1e-6)
        assert scan.frame_id == msg.header.frame_id.lstrip("/")
    assert stats.snapshot()["ros2/scan"]["invalid"] == 1  # the garbage, counted and dropped
    (payload, attachment), *_ = side.received("loci/place")
    assert json.loads(rm.decode(payload, rm.STRING).data) == place_msg and attachment is None


def test_static_transforms_published_before_the_interface_started_still_arrive() -> None:
    """/tf_static is transient local: published once by a publisher with a cache (as rmw_zenoh
    does), before the interface subscribes; the interface asks for the history and learns the mount."""
    from zenoh.ext import CacheConfig, declare_advanced_publisher

    cfg = Ros2Config(enabled=True)
    conf = zenoh.Config()
    conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("timestamping/enabled", "true")  # as rmw_zenoh's session configuration has it
    ros = zenoh.open(conf)
    try:
        loci = ros  # the agent's side plays no part here
        iface = Ros2Interface(cfg, loci, "tb3", ros_session=ros)
        link = rm.make(
            "geometry_msgs/msg/TransformStamped",
            header=rm.header(10.0, "base_link"),
            child_frame_id="laser",
            transform=rm.make(
                "geometry_msgs/msg/Transform",
                translation=rm.make("geometry_msgs/msg/Vector3", x=0.2, y=-0.05, z=0.3),
                rotation=rm.make("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )
        pub = declare_advanced_publisher(
            ros,
            iface.key(cfg.tf_static, rm.TF_MESSAGE),
            cache=CacheConfig(max_samples=1),
            publisher_detection=True,
        )
        pub.put(rm.encode(rm.make(rm.TF_MESSAGE, transforms=[link])))
        time.sleep(0.3)

        async def main() -> None:
            task = asyncio.create_task(iface.run())
            await asyncio.wait_for(iface.ready.wait(), 10)
            for _ in range(100):
                if iface.tf.mount("base_link", "laser") is not None:
                    break
                await asyncio.sleep(0.05)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task

        asyncio.run(main())
        pub.undeclare()
    finally:
        ros.close()
    mount = iface.tf.mount("base_link", "laser")
    assert mount is not None and mount.pose == pytest.approx((0.2, -0.05, 0.0))
