"""The agent end to end: ``loci run`` as a process, a virtual LMS on a real pty, real Zenoh.

The robot is scripted: a path through a generated office (corridor, a door, the room
behind it) as a function of wall-clock time. The virtual LMS scans from the path's pose
and a tiny fake base in the test publishes the same pose as odometry on
``loci/<robot>/odom`` at 50 Hz. The agent connects to the test's Zenoh session.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from support.runtime import ROBOT, AgentProcess, _room_scan, write_config

from agent.bus.bridge import publish_stream
from agent.bus.codecs import POSE_CODEC
from agent.bus.queryable import query_state
from agent.bus.ready import ready_roles
from agent.bus.schemas import SCHEMAS
from agent.bus.session import BusConfig, bus_session, listening_endpoints
from agent.bus.testing import settle, wait_until
from agent.config import load_config
from agent.core.pipeline import areas_message, graph_message
from agent.recording.offline import replay_recording
from agent.recording.replay import McapMessages
from agent.runtime import Agent
from drivers.messages import Pose2D
from drivers.sim.lms import VirtualLMS
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.model import PlaceModel, default_model_path
from sim.buildings import generate_building
from sim.lms_world import LmsWorld

REPO = Path(__file__).resolve().parents[2]
SPEED = 1.0  # m/s
TURN_RATE = 2.0  # rad/s


class ScriptedRobot:
    """A path through building 1: 2 m of corridor, a turn, through a door 1.6 m into the room.

    The pose is a function of wall-clock time; the robot waits at the start until
    :meth:`go` and stops at the end of the path.
    """

    def __init__(self) -> None:
        b = generate_building(1, furniture=False, layout="straight")
        door = next(d for d in b.doors if b.space(d.connects[1]).kind == "corridor" and d.center[0] > 5.0)
        n = np.array([math.cos(door.orientation), math.sin(door.orientation)])
        along = np.array([-n[1], n[0]])
        c = np.array(door.center)
        x0, y0, x1, y1 = b.space(door.connects[1]).rect
        front = c + n * float(np.dot(np.array([(x0 + x1) / 2, (y0 + y1) / 2]) - c, n))
        self.grid = b.grid
        self.door = door
        self.points = [front + 2.0 * along, front, c - 1.6 * n]
        self.t0 = math.inf
        self.duration = sum(np.hypot(*(q - p)) for p, q in itertools.pairwise(self.points)) / SPEED + 1.5

    def go(self) -> None:
        self.t0 = time.time()

    def pose(self) -> tuple[float, float, float]:
        t = max(0.0, time.time() - self.t0)
        heading: float | None = None
        for a, b in itertools.pairwise(self.points):
            d = b - a
            h = math.atan2(d[1], d[0])
            if heading is not None:
                turn = math.atan2(math.sin(h - heading), math.cos(h - heading))
                if t < abs(turn) / TURN_RATE:
                    return (a[0], a[1], heading + math.copysign(TURN_RATE * t, turn))
                t -= abs(turn) / TURN_RATE
            length = float(np.hypot(*d))
            if t < length / SPEED:
                return (a[0] + d[0] * t * SPEED / length, a[1] + d[1] * t * SPEED / length, h)
            t -= length / SPEED
            heading = h
        return (float(self.points[-1][0]), float(self.points[-1][1]), heading or 0.0)


class FakeBase:
    """Publishes the robot's pose as odometry at 50 Hz from a thread."""

    def __init__(self, session: zenoh.Session, robot: ScriptedRobot) -> None:
        self._pub = publish_stream(session, ROBOT, "odom")
        self._robot = robot
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            x, y, th = self._robot.pose()
            self._pub.put(Pose2D(x, y, th, stamp=time.time()))
            self._stop.wait(0.02)

    def __enter__(self) -> FakeBase:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._pub.close()


class Collector:
    """Raw callback subscribers in the test's session: every sample of a robot stream."""

    def __init__(self, session: zenoh.Session, streams: list[str]) -> None:
        self.samples: dict[str, list[bytes]] = {s: [] for s in streams}
        self._subs = [session.declare_subscriber(f"loci/{ROBOT}/{s}", self._on(s)) for s in streams]

    def _on(self, stream: str) -> Callable[[zenoh.Sample], None]:
        def cb(sample: zenoh.Sample) -> None:
            self.samples[stream].append(sample.payload.to_bytes())

        return cb

    def json(self, stream: str) -> list[dict[str, Any]]:
        return [json.loads(b) for b in self.samples[stream]]


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[tuple[ScriptedRobot, VirtualLMS, zenoh.Session, str]]:
    robot = ScriptedRobot()
    world = LmsWorld(robot.grid, lambda t: robot.pose(), noise_std=0.01, seed=0)
    with VirtualLMS(world, link=tmp_path / "lms0") as lms, bus_session(BusConfig()) as session:
        (endpoint,) = listening_endpoints(session)
        yield robot, lms, session, endpoint


def comparable(doc: dict[str, Any]) -> tuple[Any, Any]:
    g, a = graph_message(doc, 0.0), areas_message(doc, 0.0)
    return (g["nodes"], g["edges"]), a["areas"]


def test_live_run_publishes_answers_records_and_replays_to_the_same_map(
    tmp_path: Path, sim: tuple[ScriptedRobot, VirtualLMS, zenoh.Session, str]
) -> None:
    robot, lms, session, endpoint = sim
    config = write_config(tmp_path, endpoint, lms.link)
    out = tmp_path / "run.mcap"
    seen = Collector(
        session,
        [
            "place",
            "graph",
            "areas",
            "diagnostics",
            "graph/scene",
            "tf",
            "scan/full",
            "people",
            "people/scene",
        ],
    )
    with FakeBase(session, robot):
        agent = AgentProcess(config, "--record", str(out))
        try:
            agent.wait_ready()
            robot.go()
            time.sleep(1.0)
            # malformed odometry: bad protobuf bytes, and JSON on a protobuf stream
            key = f"loci/{ROBOT}/odom"
            session.put(key, b"\x0a\x03xyz\xff", encoding=zenoh.Encoding(POSE_CODEC.zenoh_encoding))
            session.put(
                key, b'{"schema":"loci.place/1"}', encoding=zenoh.Encoding("application/json;loci.place/1")
            )
            time.sleep(robot.duration - 1.0)
            replies = {
                r.key.rsplit("/", 1)[-1]: r for r in query_state(session, f"loci/{ROBOT}/state/**", 3.0)
            }
            ready_while_running = ready_roles(session, ROBOT)
            rc = agent.stop()
        finally:
            agent.kill()
    assert rc == 0, "".join(agent.lines)
    # the agent said it was ready (its first scan processed), and is no more once stopped
    assert ready_while_running == {"agent"} and ready_roles(session, ROBOT) == set()
    summary = agent.summary()
    # every scan the agent got was processed: nothing dropped anywhere
    assert summary["dropped"] == 0 and summary["errors"] == 0, summary
    # (a scan still waiting for its odometry when the stop came is "unfinished", not lost:
    # on a loaded machine the last few can be)
    unfinished = summary["sync"]["unfinished"]
    assert summary["scans_processed"] + unfinished == summary["scans_fed"] > 100, summary
    assert unfinished <= 10, summary
    assert summary["invalid"] == {"odom": 2}, summary
    # published on the bus, and answerable by the queryables
    assert set(replies) == {"graph", "areas", "place"} and all(r.value for r in replies.values())
    graph, areas = replies["graph"].value, replies["areas"].value
    assert graph is not None and areas is not None
    kinds = [n["kind"] for n in graph["nodes"]]
    assert kinds.count("place") >= 3 and kinds.count("doorway") == 1
    assert len(areas["areas"]) == 2
    assert len(seen.samples["place"]) >= 0.9 * summary["scans_processed"]
    # (sensor-class streams publish with congestion control DROP: a sample may go missing)
    assert min(len(seen.samples["tf"]), len(seen.samples["scan/full"])) >= 0.9 * summary["scans_processed"]
    # people ([people] is on by default): only scans with legs or tracks (and one empty
    # message after them) are published, in the odometry frame
    people = seen.json("people")
    assert len(people) <= summary["scans_processed"]
    for message in people:
        SCHEMAS.validate(message)
        assert message["frame_id"] == "odom"
    shown = [bool(m["legs"] or m["tracks"]) for m in people]
    # an empty message only ever follows one with people (it clears the picture), so there
    # are never more empty ones than others; not "never two in a row": the stream publishes
    # with congestion control DROP, and a lost message between two empty ones joins them
    assert shown.count(False) <= shown.count(True) + 1, shown
    assert seen.json("graph")[-1]["nodes"] == graph["nodes"] and seen.samples["graph/scene"]
    assert seen.json("areas")[-1]["areas"] == areas["areas"]
    diag = seen.json("diagnostics")
    assert diag and diag[-1]["extra"]["final"]["scans_fed"] == summary["scans_fed"]
    assert max(d["streams"]["odom"]["invalid"] for d in diag) == 2
    for message in (seen.json("place")[-1], diag[-1]):
        SCHEMAS.validate(message)
    # the state on disk is the map the queryables served
    state = json.loads((tmp_path / "state" / "navgraph.json").read_text())
    assert comparable(state) == ((graph["nodes"], graph["edges"]), areas["areas"])
    # the recording is complete and holds every scan the agent processed
    messages = McapMessages(out)
    topics: dict[str, int] = {}
    for rec in messages:
        topics[rec.topic] = topics.get(rec.topic, 0) + 1
    assert not messages.truncated
    assert (
        topics[f"loci/{ROBOT}/scan"]
        == summary["scans_fed"]
        == summary["recorded"] - sum(v for k, v in topics.items() if not k.endswith("/scan"))
    )
    # loci replay of the recording builds the same graph and areas
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "agent.cli",
            "replay",
            str(out),
            "--json",
            "--out-dir",
            str(tmp_path / "replay"),
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    replayed = json.loads(result.stdout)
    assert (replayed["graph"]["nodes"], replayed["graph"]["edges"]) == (graph["nodes"], graph["edges"])
    assert replayed["areas"]["areas"] == areas["areas"]
    assert replayed["stats"]["processed"] == summary["scans_processed"] and replayed["stats"]["invalid"] == 2
    assert comparable(json.loads((tmp_path / "replay" / "navgraph.json").read_text())) == comparable(state)


def test_a_killed_agent_resumes_with_its_map(
    tmp_path: Path, sim: tuple[ScriptedRobot, VirtualLMS, zenoh.Session, str]
) -> None:
    robot, lms, session, endpoint = sim
    config = write_config(tmp_path, endpoint, lms.link)
    state_file = tmp_path / "state" / "navgraph.json"

    def saved_nodes() -> int:
        try:
            return len(json.loads(state_file.read_text())["nodes"])
        except (FileNotFoundError, ValueError):
            return 0

    with FakeBase(session, robot):
        first = AgentProcess(config)
        try:
            first.wait_ready()
            robot.go()
            assert wait_until(lambda: saved_nodes() >= 2, timeout=robot.duration), "".join(first.lines)
            first.proc.send_signal(signal.SIGKILL)
            first.proc.wait(10)
        finally:
            first.kill()
        killed = json.loads(state_file.read_text())  # written atomically: never torn by the kill
        second = AgentProcess(config, "--record", str(tmp_path / "resumed.mcap"))
        try:
            second.wait_ready()
            (reply,) = query_state(session, f"loci/{ROBOT}/state/graph", 3.0)
            assert reply.value is not None, reply.error
            before = {n["id"]: n for n in graph_message(killed, 0.0)["nodes"]}
            now = {n["id"]: n for n in reply.value["nodes"]}
            for k, n in before.items():
                assert now[k]["kind"] == n["kind"] and (now[k]["x"], now[k]["y"]) == (n["x"], n["y"])
            time.sleep(1.0)
            assert second.stop() == 0, "".join(second.lines)
        finally:
            second.kill()
    final = json.loads(state_file.read_text())
    assert {n["id"] for n in killed["nodes"]} <= {n["id"] for n in final["nodes"]}
    # the recording of the resumed run carries the map it started from: its replay ends where the run did
    model = PlaceModel.load(default_model_path())
    res = replay_recording(tmp_path / "resumed.mcap", model=model)
    assert res.resumed and res.pipeline.scans == second.summary()["scans_processed"]
    assert comparable(res.pipeline.state_document()) == comparable(final)


def test_agent_on_bus_scans_waits_out_stopped_odometry_and_ignores_bad_messages(tmp_path: Path) -> None:
    occ = np.ones((82, 162), dtype=bool)
    occ[1:-1, 1:-1] = False
    grid = OccupancyGrid.from_masks(occ, 0.05, name="room")  # an 8 m x 4 m room
    model = PlaceModel.load(default_model_path())

    async def main() -> None:
        with bus_session(BusConfig()) as session:
            (endpoint,) = listening_endpoints(session)
            cfg = load_config(write_config(tmp_path, endpoint, None), env={})
            stop = asyncio.Event()
            ready = asyncio.Event()
            agent = Agent(cfg, model=model, on_ready=lambda _: ready.set())
            run = asyncio.create_task(agent.run(stop))
            await asyncio.wait_for(ready.wait(), 20)
            assert agent.session is not None
            await asyncio.to_thread(settle, session, agent.session)
            scans, odom = publish_stream(session, ROBOT, "scan"), publish_stream(session, ROBOT, "odom")
            seq = 0

            async def drive(seconds: float, *, with_odometry: bool) -> None:
                nonlocal seq
                t_end = time.time() + seconds
                while time.time() < t_end:
                    now = time.time()
                    pose = (1.0 + 0.5 * (seq * 0.05), 2.0, 0.0)
                    if with_odometry:
                        odom.put(Pose2D(*pose, stamp=now))
                    if seq % 2 == 0 or not with_odometry:
                        scans.put(_room_scan(grid, pose, now, seq))
                    seq += 1
                    await asyncio.sleep(0.025)

            await drive(1.0, with_odometry=True)
            await asyncio.sleep(0.2)
            processed = agent.pipeline.scans if agent.pipeline else 0
            assert processed >= 10 and agent.sync.stats.dropped == 0
            # odometry stops: scans wait max_wait (0.2 s), then are dropped; nothing changes
            nodes = len(agent.pipeline.graph) if agent.pipeline else 0
            await drive(0.6, with_odometry=False)
            await asyncio.sleep(0.4)
            assert agent.pipeline is not None and agent.pipeline.scans == processed
            assert agent.sync.stats.no_odometry >= 10 and len(agent.pipeline.graph) == nodes
            # malformed scans: counted and ignored
            session.put(
                f"loci/{ROBOT}/scan",
                b"garbage",
                encoding=zenoh.Encoding("application/protobuf;foxglove.LaserScan"),
            )
            session.put(f"loci/{ROBOT}/scan", b'{"x": 1}', encoding=zenoh.Encoding("application/json"))
            # one valid odometry sample and one scan stamped 10⁶ s ahead (a wrong clock, or a
            # forged message) are refused: they used to stop classification until a restart
            odom.put(Pose2D(3.0, 2.0, 0.0, stamp=time.time() + 1e6))
            scans.put(_room_scan(grid, (3.0, 2.0, 0.0), time.time() + 1e6, 10**6))
            # odometry is back: processing resumes
            await drive(1.0, with_odometry=True)
            await asyncio.sleep(0.3)
            assert agent.pipeline.scans >= processed + 10
            assert agent.sync.stats.odom_future == 1 and agent.sync.stats.future_stamp == 1
            stop.set()
            report = await asyncio.wait_for(run, 10)
            assert report.invalid == {"scan": 2}
            assert report.drops["no_odometry"] == agent.sync.stats.no_odometry
            assert report.scans_processed == agent.pipeline.scans and report.errors == 0
            assert (tmp_path / "state" / "navgraph.json").is_file() and report.saves >= 1
            assert agent.session is None  # closed

    asyncio.run(main())
