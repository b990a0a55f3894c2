"""The Foxglove live view, watched by a real WebSocket client on loopback.

The client (:mod:`agent.live.probe`) speaks the Foxglove protocol and decodes every message
with the schema the server advertised (Google's protobuf runtime on the advertised
FileDescriptorSet; JSON), so these tests check what a Foxglove app would get, not what our
encoders think they sent.
"""

from __future__ import annotations

import asyncio
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from support.recordings import REPO, Run, make_run, write_recording

from agent.live import layers
from agent.live.config import FoxgloveConfig, parse_address
from agent.live.probe import connect
from agent.live.server import TOPICS, LabelledMap, LiveView
from knowledge import labels as lbl
from knowledge.errors import ConfigError
from knowledge.label_maps import label_map_yaml

PER_SCAN = {"/scan", "/scan/full", "/tf", "/place", "/map"}
STATE = {"/graph", "/areas", "/labels"}


@pytest.fixture(scope="module")
def run() -> Run:
    return make_run()


def test_addresses() -> None:
    assert parse_address("8765") == ("127.0.0.1", 8765)
    assert parse_address("0.0.0.0:9000") == ("0.0.0.0", 9000)
    assert parse_address("[::1]:0") == ("::1", 0)
    for bad in ("", "host:", "70000", "x:y"):
        with pytest.raises(ValueError, match=r"\[HOST:\]PORT"):
            parse_address(bad)
    with pytest.raises(ValueError):
        FoxgloveConfig(listen="nope")


def test_config_section() -> None:
    from agent.config import load_config

    c = load_config(table={"foxglove": {"listen": "0.0.0.0:8765", "grid_period": 0.5}}, env={})
    assert c.foxglove.on and c.foxglove.address == ("0.0.0.0", 8765)
    assert not load_config(table={}, env={}).foxglove.on
    with pytest.raises(ConfigError, match="foxglove"):
        load_config(table={"foxglove": {"listen": "x:y"}}, env={})


def test_transform_chain_puts_the_laser_where_the_pipeline_had_it() -> None:
    mount = (0.3, -0.1, 0.2)
    laser = (2.0, 1.0, 0.7)
    bx, by, bth = layers.base_pose(laser, mount)
    # compose base ⊕ mount again
    c, s = math.cos(bth), math.sin(bth)
    assert (bx + c * mount[0] - s * mount[1], by + s * mount[0] + c * mount[1]) == pytest.approx(laser[:2])
    assert bth + mount[2] == pytest.approx(laser[2])


def _labels_yaml(tmp_path: Path) -> Path:
    codes = np.zeros((40, 60), np.uint8)
    codes[5:20, 5:30] = lbl.ROOM
    codes[25:35, :] = lbl.CORRIDOR
    lbl.write_label_image(tmp_path / "labels.png", codes)
    (tmp_path / "labels.yaml").write_text(label_map_yaml("labels.png", 0.1, (-2.0, -1.0, 0.0)))
    return tmp_path / "labels.yaml"


def test_nothing_is_built_while_nobody_watches(tmp_path: Path) -> None:
    """With the server up but no client, on_step returns at once: no message is encoded."""
    live = LiveView("127.0.0.1", 0, labels=LabelledMap.load(_labels_yaml(tmp_path)))
    try:

        class Boom:
            def __getattr__(self, name: str) -> object:
                raise AssertionError(f"on_step read result.{name} with nobody watching")

        live.on_step(Boom())
        assert not live.watched and sum(live.sent.values()) == 0
    finally:
        live.close()


@pytest.mark.slow
def test_replay_served_live_to_a_real_client(tmp_path: Path, run: Run) -> None:
    rec = tmp_path / "run.mcap"
    write_recording(rec, run)
    labels = _labels_yaml(tmp_path)
    proc = subprocess.Popen(
        [
            sys.executable, "-m", "agent.cli", "-q", "replay", str(rec), "--foxglove", "127.0.0.1:0",
            "--speed", "3", "--linger", "20", "--labels", str(labels),
        ],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stderr is not None
        line = proc.stderr.readline()
        m = re.search(r"ws://127\.0\.0\.1:(\d+)", line)
        assert m, line
        end_ns = int(run.scans[-1].stamp * 1e9)
        got, advertised = asyncio.run(_watch(f"ws://127.0.0.1:{m.group(1)}", PER_SCAN | STATE, end_ns))
    finally:
        proc.terminate()
        proc.communicate(timeout=20)
    assert set(advertised) == set(TOPICS)
    assert {t: advertised[t]["schemaName"] for t in ("/scan", "/map", "/graph", "/tf", "/place")} == {
        "/scan": "foxglove.LaserScan",
        "/map": "foxglove.Grid",
        "/graph": "foxglove.SceneUpdate",
        "/tf": "foxglove.FrameTransforms",
        "/place": "loci.place/1",
    }
    missing = (PER_SCAN | STATE) - set(got)
    assert not missing, f"no message on {missing}"
    # the scan as measured: 360 beams over the full turn, the recorded ranges
    scan = got["/scan"][-1].value
    assert scan.frame_id == "laser" and len(scan.ranges) == 360
    stamps = [s.stamp for s in run.scans]
    t = scan.timestamp.seconds + scan.timestamp.nanos * 1e-9
    i = int(np.argmin(np.abs(np.array(stamps) - t)))
    assert abs(stamps[i] - t) < 1e-6
    assert np.allclose(scan.ranges, run.scans[i].ranges, atol=1e-5)
    # the transforms: map → odom → base_link → laser, the laser where the odometry put it
    tf = got["/tf"][-1].value
    chain = [(f.parent_frame_id, f.child_frame_id) for f in tf.transforms]
    assert chain == [("map", "odom"), ("odom", "base_link"), ("base_link", "laser")]
    t = tf.transforms[1].timestamp.seconds + tf.transforms[1].timestamp.nanos * 1e-9
    pose = min(run.scan_poses, key=lambda p: abs(p.stamp - t))
    assert tf.transforms[1].translation.x == pytest.approx(pose.x, abs=1e-6)
    # the place: a loci.place/1 whose histogram sums to 1
    place = got["/place"][-1].value
    assert place["schema"] == "loci.place/1" and sum(place["probabilities"].values()) == pytest.approx(
        1, abs=1e-3
    )
    # the occupancy grid: RGBA + occupancy cells, some occupied (the corridor walls), in odom
    grid = got["/map"][-1].value
    assert grid.frame_id == "odom" and [f.name for f in grid.fields] == [
        "red",
        "green",
        "blue",
        "alpha",
        "occupancy",
    ]
    cells = np.frombuffer(grid.data, np.uint8).reshape(-1, grid.column_count, 5)
    occ = cells[..., 4].view(np.int8)
    assert (occ == 100).sum() > 50 and (occ == 0).sum() > 500
    # the labelled map: placed as its YAML says, the class codes kept
    lab = got["/labels"][-1].value
    assert lab.frame_id == "map" and lab.column_count == 60
    assert (lab.pose.position.x, lab.pose.position.y) == pytest.approx((-2.0, -1.0))
    codes = np.frombuffer(lab.data, np.uint8).reshape(40, 60, 5)[::-1, :, 4]
    assert np.array_equal(codes, lbl.read_label_image(tmp_path / "labels.png"))
    # the graph and the areas: spheres for nodes, a text per area with its class and id
    graph = got["/graph"][-1].value
    assert len(graph.entities[0].spheres) >= 3
    areas = got["/areas"][-1].value
    assert all(re.match(r"(room|corridor|doorway|hallway|\?) #\d+", t.text) for t in areas.entities[0].texts)
    assert areas.entities[0].texts


async def _watch(url: str, wanted: set[str], end_ns: int) -> tuple[dict[str, list], dict[str, dict]]:  # type: ignore[type-arg]
    """Every message until each wanted topic has one and the last scan's place came (or 60 s)."""
    probe = await connect(url, timeout=30)
    try:
        await probe.subscribe()
        got = await probe.collect(wanted, timeout=60)
        while not any(r.log_time >= end_ns for r in got.get("/place", ())):
            r = await probe.receive(30)
            if r is None:
                break
            got.setdefault(r.topic, []).append(r)
        return got, probe.topics
    finally:
        await probe.close()


def test_the_committed_layout_is_the_one_built() -> None:
    import json as _json

    from agent.live.layout import LAYOUT_FILE, layout_json

    assert LAYOUT_FILE.read_text() == layout_json(), "regenerate it: python -m agent.live.layout"
    text = LAYOUT_FILE.read_text()
    doc = _json.loads(text)
    assert doc["content"]
    # every topic the layout names is one the live view serves
    named = set(re.findall(r'"(/[a-z/]+)(?:\.|")', text))
    assert named and named <= set(TOPICS), named - set(TOPICS)


@pytest.mark.slow
def test_the_running_agent_serves_its_layers_and_the_conversation(tmp_path: Path) -> None:
    """``loci run`` with [foxglove]: scans from the bus, a client connected to the agent's
    server gets the per-scan layers and what the robot says (an ask_place intent)."""
    from support.runtime import ROBOT, _room_scan, write_config

    from agent.bus.bridge import publish_stream
    from agent.bus.session import BusConfig, bus_session, listening_endpoints
    from agent.bus.testing import settle
    from agent.config import load_config
    from agent.runtime import Agent
    from drivers.messages import Pose2D
    from knowledge.metric.grid import OccupancyGrid
    from knowledge.places.model import PlaceModel, default_model_path

    occ = np.ones((82, 162), dtype=bool)
    occ[1:-1, 1:-1] = False
    grid = OccupancyGrid.from_masks(occ, 0.05, name="room")
    model = PlaceModel.load(default_model_path())

    async def main() -> dict[str, list]:  # type: ignore[type-arg]
        with bus_session(BusConfig()) as session:
            (endpoint,) = listening_endpoints(session)
            cfg = load_config(
                write_config(tmp_path, endpoint, None, foxglove='listen = "127.0.0.1:0"\ngrid_period = 0.2'),
                env={},
            )
            stop, ready = asyncio.Event(), asyncio.Event()
            agent = Agent(cfg, model=model, on_ready=lambda _: ready.set())
            run = asyncio.create_task(agent.run(stop))
            await asyncio.wait_for(ready.wait(), 30)
            assert agent.live is not None and agent.session is not None
            await asyncio.to_thread(settle, session, agent.session)
            probe = await connect(agent.live.url)
            await probe.subscribe()
            scans, odom = publish_stream(session, ROBOT, "scan"), publish_stream(session, ROBOT, "odom")
            intents = publish_stream(session, ROBOT, "dialogue/intent")
            got: dict[str, list] = {}  # type: ignore[type-arg]
            for seq in range(40):
                now = time.time()
                pose = (1.0 + 0.05 * seq, 2.0, 0.0)
                odom.put(Pose2D(*pose, stamp=now))
                scans.put(_room_scan(grid, pose, now, seq))
                if seq == 20:
                    intents.put(
                        {
                            "schema": "loci.intent/1",
                            "intent": "ask_place",
                            "id": "q1",
                            "speaker": "tutor",
                            "args": {},
                        }
                    )
                while (r := await probe.receive(0.02)) is not None:
                    got.setdefault(r.topic, []).append(r)
            more = await probe.collect({"/conversation", "/map"}, timeout=5)
            for k, v in more.items():
                got.setdefault(k, []).extend(v)
            await probe.close()
            stop.set()
            await asyncio.wait_for(run, 20)
            return got

    got = asyncio.run(main())
    assert {"/scan", "/tf", "/place", "/graph", "/map", "/conversation"} <= set(got), set(got)
    said = [r.value.message for r in got["/conversation"]]
    assert said and all(isinstance(s, str) and s for s in said)
    assert got["/place"][-1].value["schema"] == "loci.place/1"


def test_areas_carry_the_names_the_conceptual_map_has_for_them() -> None:
    import base64

    from foxglove import messages as fg

    from agent.live.probe import _make_decoder

    schema = fg.SceneUpdate.get_schema()
    decode = _make_decoder(
        {
            "topic": "/areas",
            "encoding": "protobuf",
            "schemaName": schema.name,
            "schema": base64.b64encode(schema.data).decode(),
        }
    )
    graph = {
        "nodes": [{"id": 1, "x": 0.0, "y": 0.0}, {"id": 2, "x": 2.0, "y": 0.0}, {"id": 3, "x": 9.0, "y": 9.0}]
    }
    areas = {
        "stamp": 3.0,
        "areas": [{"id": 7, "label": "room", "nodes": [1, 2]}, {"id": 8, "label": None, "nodes": [3]}],
    }
    snapshot = {
        "areas": {
            "7": {"id": 7, "names": ["kitchen"], "types": ["Kitchen"]},
            "8": {"id": 8, "names": [], "types": []},
        }
    }
    names = layers.area_names(snapshot)
    assert names == {7: ["kitchen", "Kitchen"]}
    scene = decode(layers.named_areas_scene(areas, graph, names).encode())
    texts = {t.text: (t.pose.position.x, t.pose.position.y) for t in scene.entities[0].texts}
    assert texts == {"room #7\nkitchen, Kitchen": (1.0, 0.0), "? #8": (9.0, 9.0)}
