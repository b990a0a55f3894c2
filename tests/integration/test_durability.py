"""Durable before acknowledged (issue 18, failure 5): a fact the robot said "ok" to survives a
SIGKILL that comes right after the "ok".

``loci run`` runs as a process with the conceptual map on (SQLite, HermiT) and a hand-made
map of a corridor, a door and a room. The test speaks to it as the dialogue process does,
and kills it with SIGKILL from inside the callback that receives the last acknowledgement
(no time for a debounced save or a reasoning to finish). Before the fix, 10 of 82 names
acknowledged 0.03-0.88 s before a kill were gone after the restart.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh
from support.navigation import small_map
from support.runtime import AgentProcess

from agent.bus.bridge import publish_stream
from agent.bus.session import BusConfig, bus_session, listening_endpoints
from knowledge.conceptual import ConceptualMap
from knowledge.topology import persistence
from knowledge.topology.areas import AreaMap
from tools.crash import agent_config

REPO = Path(__file__).resolve().parents[2]
ROBOT = "durabot"


class Acks:
    """Replies on ``dialogue/say``; SIGKILLs the agent from the callback that gets ``kill_on``'s reply."""

    def __init__(self, session: zenoh.Session) -> None:
        self.replies: dict[str, dict[str, Any]] = {}
        self.kill_on: str | None = None
        self.pid: int | None = None
        self.killed = threading.Event()
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(f"loci/{ROBOT}/dialogue/say", self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        msg = json.loads(sample.payload.to_bytes())
        iid = msg.get("in_reply_to")
        if iid is not None and iid == self.kill_on and self.pid is not None:
            os.kill(self.pid, signal.SIGKILL)  # at once: the reply has just left the agent
            self.killed.set()
        with self._cond:
            if iid is not None:
                self.replies[iid] = msg
            self._cond.notify_all()

    def wait(self, iid: str, timeout: float = 30.0) -> dict[str, Any]:
        with self._cond:
            if not self._cond.wait_for(lambda: iid in self.replies, timeout):
                raise AssertionError(f"no reply to {iid}")
            return self.replies[iid]


@pytest.mark.slow
def test_every_acknowledged_fact_survives_a_sigkill_right_after_the_acknowledgement(tmp_path: Path) -> None:
    graph = small_map()
    areas = AreaMap()
    areas.update(graph)
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "navgraph.json").write_text(
        persistence.dumps(persistence.to_document(graph, areas))
    )
    room = areas.area_of(graph.current)
    assert room is not None
    acknowledged: list[tuple[str, str]] = []  # (kind, word) the robot said ok to
    n = itertools.count(1)
    with bus_session(BusConfig()) as session:
        (endpoint,) = listening_endpoints(session)
        config = agent_config(tmp_path, endpoint, ROBOT)
        acks = Acks(session)
        intents = publish_stream(session, ROBOT, "dialogue/intent")
        for cycle in range(2):
            agent = AgentProcess(config)
            try:
                agent.wait_ready(60.0)
                acks.pid = agent.proc.pid
                deadline = time.monotonic() + 10
                while time.monotonic() < deadline:  # the agent's intent subscriber reached us
                    iid = f"probe-{next(n)}"
                    intents.put(_intent(iid, "ask_place", {}))
                    try:
                        acks.wait(iid, 0.5)
                        break
                    except AssertionError:
                        continue
                said = [("name", f"the {word} room {cycle}") for word in ("quiet", "blue", "third")]
                said.append(("object", "couch" if cycle else "chair"))
                for i, (kind, word) in enumerate(said):
                    iid = f"c{cycle}-{i}"
                    if i == len(said) - 1:
                        acks.kill_on = iid
                    args = {"name": word} if kind == "name" else {"object": word}
                    intents.put(_intent(iid, f"assert_{kind}", args))
                    reply = acks.wait(iid)
                    assert reply["status"] == "ok", reply
                    acknowledged.append((kind, word))
                assert acks.killed.wait(5)
                acks.killed.clear()
                assert agent.proc.wait(10) == -signal.SIGKILL
            finally:
                agent.kill()
    # every fact the robot acknowledged is in the conceptual map on disk
    m = ConceptualMap(tmp_path / "state" / "concepts.sqlite3")
    try:
        snap = m.snapshot()
    finally:
        m.close()
    names = set(snap["areas"].get(str(room.id), {}).get("names", []))
    objects = {name for name, o in snap["objects"].items() if o["area"] == room.id}
    lost = [w for k, w in acknowledged if w not in (names if k == "name" else objects)]
    assert len(acknowledged) == 8 and not lost, f"lost after SIGKILL: {lost}"


def _intent(iid: str, kind: str, args: dict[str, Any]) -> dict[str, Any]:
    return {"schema": "loci.intent/1", "id": iid, "speaker": "tutor", "intent": kind, "args": args}
