"""The dialogue inside the running agent, over real Zenoh sessions on loopback.

The agent resumes a hand-made map (a corridor, a door, a room, and a false doorway in the
room: a bucket near a table); the test speaks to it as the dialogue process does
(``loci/<r>/dialogue/intent``) and listens to ``dialogue/say``, ``dialogue/ask`` and
``base/goal``.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import time
from pathlib import Path
from typing import Any

import zenoh

from agent.bus.bridge import publish_stream
from agent.bus.queryable import query_state
from agent.bus.schemas import SCHEMAS
from agent.bus.session import BusConfig, bus_session, listening_endpoints
from agent.bus.testing import settle
from agent.config import load_config
from agent.runtime import Agent
from knowledge.navigation.graph import DOORWAY, PLACE, GraphParams, NavigationGraph
from knowledge.places.model import PlaceModel, default_model_path
from knowledge.topology import persistence
from knowledge.topology.areas import AreaMap

ROBOT = "talkbot"


def tour_map() -> tuple[NavigationGraph, dict[str, Any]]:
    """Corridor (0..5, 0), a door at (5, 1), a room (5..6, 2..3), a false doorway at (7, 2.5)
    and the room's far part (8..9, 2..3)."""
    g = NavigationGraph(GraphParams(node_distance=1.0))
    corridor = [g.add_node(PLACE, (float(x), 0.0), votes={"corridor": 5}).id for x in range(6)]
    for a, b in itertools.pairwise(corridor):
        g.add_edge(a, b)
    door = g.add_node(DOORWAY, (5.0, 1.0), width=0.9, orientation=math.pi / 2).id
    near = [
        g.add_node(PLACE, xy, votes={"room": 5}).id for xy in ((5.0, 2.0), (6.0, 2.0), (5.0, 3.0), (6.0, 3.0))
    ]
    g.add_edge(corridor[-1], door)
    g.add_edge(door, near[0])
    for a, b in ((0, 1), (0, 2), (1, 3), (2, 3)):
        g.add_edge(near[a], near[b])
    bucket = g.add_node(DOORWAY, (7.0, 2.5), width=0.8, orientation=0.0).id
    far = [g.add_node(PLACE, xy, votes={"room": 5}).id for xy in ((8.0, 2.0), (8.0, 3.0))]
    g.add_edge(near[1], bucket)
    g.add_edge(bucket, far[0])
    g.add_edge(far[0], far[1])
    g.current = far[1]
    ids = {"corridor": corridor, "door": door, "near": near, "bucket": bucket, "far": far}
    return g, ids


class Heard:
    """Every sample of some of the robot's streams, decoded."""

    def __init__(self, session: zenoh.Session, streams: list[str]) -> None:
        self.messages: dict[str, list[dict[str, Any]]] = {s: [] for s in streams}
        self._subs = [session.declare_subscriber(f"loci/{ROBOT}/{s}", self._on(s)) for s in streams]

    def _on(self, stream: str) -> Any:
        def cb(sample: zenoh.Sample) -> None:
            self.messages[stream].append(json.loads(sample.payload.to_bytes()))

        return cb

    async def wait(self, stream: str, pred: Any, timeout: float = 5.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for m in self.messages[stream]:
                if pred(m):
                    return m
            await asyncio.sleep(0.01)
        raise AssertionError(f"nothing matching on {stream}: {self.messages[stream]}")


def test_the_agent_answers_refuses_plans_and_asks_about_a_false_doorway(tmp_path: Path) -> None:
    graph, ids = tour_map()
    areas = AreaMap()
    areas.update(graph)
    assert len(areas.areas) == 3
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "navgraph.json").write_text(
        persistence.dumps(persistence.to_document(graph, areas))
    )
    model = PlaceModel.load(default_model_path())

    async def main() -> None:
        with bus_session(BusConfig()) as session:
            (endpoint,) = listening_endpoints(session)
            table = {
                "robot": {"name": ROBOT},
                "bus": {"listen": ["tcp/127.0.0.1:0"], "connect": [endpoint]},
                "laser": {"source": "bus"},
                "state": {"dir": str(tmp_path / "state"), "save_interval": 0.2},
            }
            cfg = load_config(table=table, env={})
            heard = Heard(session, ["dialogue/say", "dialogue/ask", "base/goal", "graph", "map/edit"])
            stop, ready = asyncio.Event(), asyncio.Event()
            agent = Agent(cfg, model=model, on_ready=lambda _: ready.set())
            run = asyncio.create_task(agent.run(stop))
            await asyncio.wait_for(ready.wait(), 30)
            assert agent.session is not None and agent.pipeline is not None
            await asyncio.to_thread(settle, session, agent.session)
            await asyncio.to_thread(settle, agent.session, session)
            intents = publish_stream(session, ROBOT, "dialogue/intent")
            n = itertools.count(1)

            def say(kind: str, **args: Any) -> str:
                iid = f"t{next(n)}"
                intents.put(
                    {"schema": "loci.intent/1", "id": iid, "speaker": "tutor", "intent": kind, "args": args}
                )
                return iid

            async def reply(iid: str) -> dict[str, Any]:
                return await heard.wait("dialogue/say", lambda m: m.get("in_reply_to") == iid)

            try:
                # "Where are you?" at the far end of the room
                r = await reply(say("ask_place"))
                far_area = agent.pipeline.areas.area_of(ids["far"][1])
                assert far_area is not None
                assert r["status"] == "ok" and r["content"]["area"]["id"] == far_area.id
                assert r["content"]["area"]["class"] == "room" and r["text"] == "I am in a room."
                # a malformed intent: counted, and answered with an error because it has an id
                session.put(
                    f"loci/{ROBOT}/dialogue/intent",
                    json.dumps({"schema": "loci.intent/1", "id": "bad-1", "speaker": "t", "intent": "dance"}),
                    encoding=zenoh.Encoding("application/json;loci.intent/1"),
                )
                session.put(f"loci/{ROBOT}/dialogue/intent", b"not json at all")
                r = await reply("bad-1")
                assert r["status"] == "error" and "dance" in r["reason"]
                # "Go to the corridor": a path over the graph through both doorways
                iid = say("go_to", target={"head": "corridor", "determiner": "the"})
                r = await reply(iid)
                goal = await heard.wait("base/goal", lambda m: str(m.get("id", "")).endswith(iid))
                SCHEMAS.validate(goal)
                path = r["content"]["path"]
                assert r["status"] == "accepted" and path[0] == ids["far"][1]
                assert ids["bucket"] in path and ids["door"] in path and path[-1] in ids["corridor"]
                # no scan yet, so no pose: the path starts at the node the robot was last at
                xy = [(p["x"], p["y"]) for p in goal["path"]]
                assert xy == [agent.pipeline.graph.node(k).xy for k in path]
                # the robot comes back to a node of the room it knows without passing the
                # bucket again (as a scan would: an edge, the areas recomputed)
                pipeline = agent.pipeline
                pipeline.graph.add_edge(ids["far"][1], ids["near"][3])
                events = pipeline.areas.update(pipeline.graph)
                assert agent.dialogue is not None
                agent.dialogue.on_area_events(events)
                agent._publish_state(time.time())
                ask = await heard.wait("dialogue/ask", lambda m: True)
                SCHEMAS.validate(ask)
                assert ask["about"] == {**ask["about"], "kind": "false_doorway", "node": ids["bucket"]}
                assert ask["text"] == "Was there a door here?"
                # "No": the doorway goes from the map; the room is one area
                r = await reply(say("answer", answer="no", question=ask["id"]))
                assert r["status"] == "ok" and r["content"]["removed"] == ids["bucket"]
                await heard.wait("graph", lambda m: all(node["id"] != ids["bucket"] for node in m["nodes"]))
                # ... and says so for recordings, so that a replay makes the same change
                edit = await heard.wait("map/edit", lambda m: True)
                SCHEMAS.validate(edit, "loci.map_edit/1")
                assert edit["op"] == "remove_doorway" and edit["node"] == ids["bucket"]
                (state,) = await asyncio.to_thread(query_state, session, f"loci/{ROBOT}/state/areas", 3.0)
                assert state.value is not None
                rooms = [a for a in state.value["areas"] if ids["near"][0] in a["nodes"]]
                assert len(state.value["areas"]) == 2 and set(ids["far"]) <= set(rooms[0]["nodes"])
                assert len(heard.messages["dialogue/ask"]) == 1
            finally:
                stop.set()
                report = await asyncio.wait_for(run, 15)
            assert report.invalid == {"dialogue/intent": 2}
            # the corrected map is what was saved
            saved = json.loads((tmp_path / "state" / "navgraph.json").read_text())
            assert ids["bucket"] not in {node["id"] for node in saved["nodes"]}

    asyncio.run(main())
