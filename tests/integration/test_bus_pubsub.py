"""Every codec's messages across two real Zenoh sessions on loopback, through the bridge."""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import zenoh

from agent.bus.bridge import BusStats, publish_stream, subscribe_stream
from agent.bus.keys import Policy
from agent.bus.testing import session_pair, settle
from drivers.messages import CameraFrame, LaserScan, Pose2D


def run(coro: Coroutine[Any, Any, Any], timeout: float = 15.0) -> Any:
    return asyncio.run(asyncio.wait_for(coro, timeout))


async def until(predicate: Callable[[], bool], timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.005)


def test_sensor_and_semantic_messages_cross_sessions() -> None:
    scan = LaserScan(
        stamp=1000.5,
        seq=3,
        frame_id="laser",
        angle_min=-math.pi / 2,
        angle_increment=math.pi / 360,
        range_max=8.0,
        ranges=np.linspace(0.5, 7.5, 361),
    )
    pose = Pose2D(2.0, -1.0, 0.75, stamp=1000.5)
    frame = CameraFrame(stamp=1000.5, seq=9, frame_id="cam", image=np.full((16, 16, 3), 128, np.uint8))
    place = {
        "schema": "loci.place/1",
        "stamp": 1000.5,
        "label": "room",
        "probabilities": {"room": 0.9, "corridor": 0.1},
        "node": None,
    }

    async def main() -> None:
        stats = BusStats()
        with session_pair() as (a, b):
            subs = {
                name: subscribe_stream(b, "rosie", name, stats=stats)
                for name in ("scan", "odom", "camera", "place")
            }
            pubs = {name: publish_stream(a, "rosie", name, stats=stats) for name in subs}
            settle(a, b)
            for name, msg in (("scan", scan), ("odom", pose), ("camera", frame), ("place", place)):
                pubs[name].put(msg)
            got = {name: await sub.recv() for name, sub in subs.items()}
            for s in subs.values():
                s.close()
        np.testing.assert_array_equal(got["scan"].ranges, scan.ranges)
        assert (got["scan"].seq, got["scan"].angle_increment) == (3, scan.angle_increment)
        assert got["odom"] == pose
        assert got["camera"].seq == 9 and got["camera"].jpeg[:2] == b"\xff\xd8"
        assert got["place"] == place
        snap = stats.snapshot()
        for name in subs:
            assert snap[name]["published"] == 1 and snap[name]["delivered"] == 1, (name, snap[name])
            assert snap[name]["invalid"] == 0

    run(main())


def test_streams_have_the_qos_of_their_policy() -> None:
    with session_pair() as (a, _):
        assert publish_stream(a, "r", "scan")._pub.congestion_control == zenoh.CongestionControl.DROP
        assert (
            publish_stream(a, "r", "dialogue/intent")._pub.congestion_control == zenoh.CongestionControl.BLOCK
        )


def test_a_subscriber_in_the_same_session_hears_its_own_publisher() -> None:
    """``loci run --record`` relies on this: the recorder shares the agent's session."""

    async def main() -> Any:
        with session_pair() as (a, _):
            sub = subscribe_stream(a, "r", "place")
            pub = publish_stream(a, "r", "place")
            pub.put({"schema": "loci.place/1", "stamp": 1.0, "label": "room", "probabilities": {}})
            msg = await sub.recv()
            sub.close()
            return msg, sub.policy

    msg, policy = run(main())
    assert msg["label"] == "room" and policy is Policy.DROP_OLDEST
