"""The scripted guided tour (the book's Sect. 7.4): the tutor's lines, walks and the checks.

:func:`play_tour` says each line of :data:`sim.tutor.SCRIPT` through a
:class:`~agent.demo.conversation.Conversation`, walks the tutor's legs, waits for the
robot's reply (and the task's report for long commands) with a per-step timeout, and checks
each step's outcome. A step that fails is recorded with what was seen and the tour goes on
(later steps may still pass); :class:`StepOutcome` holds the evidence.

Checks (``evidence`` keys name what was looked at):

* station: the reply is ``ok``, the charging station is an object of a corridor area;
* follow: the robot drove into the living room (ground truth) behind the tutor;
* no_door: the robot asked "Was there a door here?" about a node near the false doorway,
  and after "No." that node is gone from the graph;
* stop: the reply is ``ok``;
* where: the reply says "room" and the current area's class is ``room``;
* look: the report names the couch and the television;
* where_again: the reply says "living room" (the reasoner's LivingRoom);
* go_tv: the task ends ``reached``; the robot's odometry is within 0.5 m of the
  television's node;
* go_station: ``reached``; within 0.5 m of the charging station's node, and the true pose
  within 1 m of where the tour started.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from agent.demo.conversation import Conversation, Event
from sim.tour import TourWorld
from sim.tutor import SCRIPT, ScriptLine

__all__ = ["NEAR", "StepOutcome", "TourTimeouts", "play_tour"]

#: Metres: "at" a node.
NEAR = 0.5


@dataclass
class StepOutcome:
    """How one story step went."""

    step: str
    book_step: int
    text: str
    passed: bool = False
    evidence: dict[str, Any] = field(default_factory=dict)
    failure: str | None = None
    seconds: float = 0.0

    def fail(self, why: str) -> StepOutcome:
        self.passed = False
        self.failure = why if self.failure is None else f"{self.failure}; {why}"
        return self

    def as_dict(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "book_step": self.book_step,
            "text": self.text,
            "passed": self.passed,
            "failure": self.failure,
            "seconds": round(self.seconds, 2),
            "evidence": self.evidence,
        }


@dataclass(frozen=True)
class TourTimeouts:
    """Seconds to wait (wall clock): a reply, the tutor's walk (per simulated metre is added
    by :func:`play_tour`), the door question, a look around, a drive."""

    reply: float = 15.0
    walk: float = 40.0
    question: float = 20.0
    look: float = 30.0
    drive: float = 60.0
    reason: float = 25.0


def _area(reply: Event | None) -> Mapping[str, Any]:
    if reply is None:
        return {}
    content = reply.message.get("content") or {}
    area = content.get("area") if isinstance(content, Mapping) else None
    return area if isinstance(area, Mapping) else {}


async def _living_room_known(conv: Conversation) -> list[str] | None:
    snap = await conv.aquery("concepts")
    for area in ((snap or {}).get("areas") or {}).values():
        types = [str(t) for t in (area.get("types") or area.get("inferred") or [])]
        if "LivingRoom" in types:
            return types
    return None


async def play_tour(
    conv: Conversation,
    tour: TourWorld,
    *,
    speed: float = 1.0,
    timeouts: TourTimeouts | None = None,
    on_step: Callable[[int, ScriptLine], None] | None = None,
) -> list[StepOutcome]:
    """Play :data:`SCRIPT` (see the module docstring); returns one outcome per line.

    ``speed``: the simulator's simulated seconds per wall-clock second (walk timeouts shrink).
    """
    to = timeouts or TourTimeouts()
    out: list[StepOutcome] = []
    station_node: int | None = None
    tv_node: int | None = None
    question: Event | None = None
    walks_done = 0

    async def say(line: ScriptLine, text: str | None = None) -> tuple[Event | None, Event | None, int]:
        since = conv.say(text or line.text)
        intent = await conv.wait_intent(since, text or line.text, min(5.0, to.reply))
        if intent is None:  # the first line may be lost while the bus's routes settle: say it again
            since = conv.say(text or line.text)
            intent = await conv.wait_intent(since, text or line.text, to.reply)
        if intent is None:
            return None, None, since
        reply = await conv.wait_reply(str(intent.message["id"]), to.reply)
        return intent, reply, since

    async def walk(legs: tuple[str, ...]) -> bool:
        nonlocal walks_done
        start = conv.latest.tutor["walks"] if conv.latest.tutor else walks_done
        for leg in legs:
            conv.walk(leg)
        metres = sum(tour.leg(leg).length for leg in legs)
        budget = to.walk + 3.0 * metres / 0.6 / speed
        target = start + len(legs)
        ok = await conv.wait_until(
            lambda: (
                conv.latest.tutor is not None
                and conv.latest.tutor["walks"] >= target
                and not conv.latest.tutor["walking"]
            ),
            budget,
        )
        walks_done = target
        return bool(ok)

    async def settle(timeout: float, still: float = 1.5) -> bool:
        """Wait until the robot has not moved more than 3 cm for ``still`` seconds."""
        deadline = time.monotonic() + timeout
        last = conv.truth_xy()
        since = time.monotonic()
        while time.monotonic() < deadline:
            await asyncio.sleep(0.2)
            now = conv.truth_xy()
            if now is None or last is None or math.dist(now, last) > 0.03:
                last, since = now, time.monotonic()
            elif time.monotonic() - since >= still:
                return True
        return False

    async def node_xy(node: int | None) -> tuple[tuple[float, float], str] | None:
        """A node's position and the frame the graph is in (``odom``, or ``map`` when the
        agent tracks its pose)."""
        if node is None:
            return None
        graph = await conv.aquery("graph") or {}
        for n in graph.get("nodes", []):
            if int(n["id"]) == node:
                return (float(n["x"]), float(n["y"])), str(graph.get("frame_id") or "odom")
        return None

    for i, line in enumerate(SCRIPT):
        if on_step is not None:
            on_step(i, line)
        t0 = time.monotonic()
        o = StepOutcome(line.step, line.book_step, line.text)
        out.append(o)
        try:
            if line.step == "no_door":
                # the robot asks about the false doorway once it has come back round the bucket
                question = question or await conv.wait_until(
                    lambda: next(
                        (e for e in conv.events if e.kind == "ask" and "door" in e.text.lower()), None
                    ),
                    to.question,
                )
                if question is None:
                    o.fail(f"the robot asked no question about a door within {to.question:.0f} s")
                    await walk(line.walk)
                    continue
                about = question.message.get("about") or {}
                o.evidence["question"] = {"text": question.text, "about": about}
                text = "No."
            else:
                text = line.text
            if line.step == "where_again":
                # the reasoner runs after the objects came in: give it its time (HermiT, Java)
                t_reason = time.monotonic()
                types = await conv.wait_until_async(_living_room_known, to.reason)
                o.evidence["reasoner_seconds"] = round(time.monotonic() - t_reason, 2)
                o.evidence["concepts_types"] = types
            intent, reply, _ = await say(line, text)
            if intent is None:
                o.fail(f"the dialogue process sent no intent for {text!r} within {to.reply:.0f} s")
                continue
            o.evidence["intent"] = intent.message.get("intent")
            if reply is None:
                o.fail(f"the robot did not reply within {to.reply:.0f} s")
                continue
            o.evidence["reply"] = {"text": reply.text, "status": reply.message.get("status")}
            if reply.message.get("status") == "error":
                o.fail(f"the robot refused: {reply.message.get('reason') or reply.text}")
            o.passed = o.failure is None
            content = reply.message.get("content") or {}

            if line.step == "station":
                area = _area(reply)
                station_node = content.get("node")
                o.evidence.update(node=station_node, area_class=area.get("class"), area=area.get("id"))
                # the class of the dead end's first node may still change as the robot drives
                # on (hallway at first): the station's area is checked once more at the end
            elif line.step == "follow":
                ok = await walk(line.walk)
                o.evidence["tutor_walked"] = list(line.walk)
                if not ok:
                    o.fail("the tutor did not finish its walk in time (was the robot left behind?)")
                await settle(10.0)
                xy = conv.truth_xy()
                inside = tour.area_at(xy) if xy is not None else None
                o.evidence["robot"] = None if xy is None else [round(v, 2) for v in xy]
                o.evidence["robot_in"] = None if inside is None else inside.name
                if inside is None or inside.name != "living room":
                    o.fail("the robot is not in the living room after following the tutor")
            elif line.step == "no_door":
                node = (question.message.get("about") or {}).get("node") if question else None
                removed = content.get("removed")
                o.evidence.update(door=node, removed=removed)
                graph = await conv.aquery("graph") or {}
                doors = [n for n in graph.get("nodes", []) if n.get("kind") == "doorway"]
                near_false = [
                    n["id"] for n in doors if math.dist((n["x"], n["y"]), tour.false_doorway.center) <= 0.6
                ]
                near_real = [
                    n["id"] for n in doors if math.dist((n["x"], n["y"]), tour.doorway.center) <= 0.6
                ]
                o.evidence.update(doorways_near_false=near_false, doorways_near_real=near_real)
                if removed is None:
                    o.fail("the robot removed no doorway")
                if near_false:
                    o.fail(f"doorway nodes {near_false} are still at the false doorway")
                if not near_real:
                    o.fail("no doorway node at the real door")
                ok = await walk(line.walk)
                if not ok:
                    o.fail("the tutor did not finish walking into the room in time")
                await settle(10.0)
            elif line.step == "where":
                area = _area(reply)
                o.evidence.update(area=area.get("id"), area_class=area.get("class"))
                if not line.reply_ok(reply.text) or area.get("class") != "room":
                    o.fail(f"expected a room, the robot said {reply.text!r}")
            elif line.step == "look":
                report = await conv.wait_task(str(intent.message["id"]), to.look)
                if report is None:
                    o.fail(f"no report of the look around within {to.look:.0f} s")
                    continue
                names = [str(x.get("name")) for x in (report.message.get("content") or {}).get("objects", [])]
                o.evidence.update(report=report.text, objects=names)
                if not line.reply_ok(" ".join(names) + " " + report.text):
                    o.fail(f"expected the couch and the television, the robot saw {names}")
            elif line.step == "where_again":
                area = _area(reply)
                o.evidence.update(area=area.get("id"), types=area.get("types"))
                if not line.reply_ok(reply.text):
                    o.fail(f"expected the living room, the robot said {reply.text!r}")
            elif line.step in ("go_tv", "go_station"):
                goal = content.get("node")
                o.evidence.update(goal_node=goal, path=content.get("path"), distance=content.get("distance"))
                report = await conv.wait_task(str(intent.message["id"]), to.drive)
                await settle(3.0, still=0.6)
                if report is None:
                    o.fail(f"the robot did not report arriving within {to.drive:.0f} s")
                else:
                    o.evidence["report"] = report.text
                    said = report.message.get("content") or {}
                    # whether the robot said it was sure where it is (False: "I think I have ...")
                    o.evidence["certain"] = said.get("certain", True)
                    if not said.get("reached"):
                        o.fail(f"the robot did not get there: {report.text}")
                want = station_node if line.step == "go_station" else tv_node
                if line.step == "go_tv":
                    want = goal
                    tv_node = goal
                found = await node_xy(want)
                # where the robot is, in the graph's frame: the odometry's pose in ``odom``; in
                # ``map`` (the tracker's frame, which starts at the true pose of the first scan)
                # the simulator's true pose, so a node mapped or reached in the wrong place fails
                target, frame = found if found is not None else (None, "odom")
                odom = conv.truth_xy() if frame == "map" else conv.odom_xy()
                if target is not None and odom is not None:
                    d = math.dist(target, odom)
                    o.evidence["metres_from_node"] = round(d, 3)
                    if d > NEAR:
                        sure = " and said it had arrived" if o.evidence.get("certain") is True else ""
                        o.fail(f"the robot stopped {d:.2f} m from node {want} (more than {NEAR} m){sure}")
                else:
                    o.fail(f"cannot measure the distance to node {want}")
                if line.step == "go_station":
                    if goal != station_node:
                        o.fail(f"the goal node {goal} is not the station's node {station_node}")
                    xy = conv.truth_xy()
                    if xy is not None:
                        d0 = math.dist(xy, tour.start[:2])
                        o.evidence["metres_from_start"] = round(d0, 3)
                        if d0 > 2 * NEAR:
                            o.fail(f"the robot is {d0:.2f} m from where the tour started")
            elif line.step == "stop":
                pass
        finally:
            o.passed = o.failure is None
            o.seconds = time.monotonic() - t0
    station = next(o for o in out if o.step == "station")
    if station.passed:
        areas = await conv.aquery("areas") or {}
        cls = next((a["label"] for a in areas.get("areas", []) if station_node in a["nodes"]), None)
        station.evidence["area_class_at_end"] = cls
        if cls != "corridor":
            station.fail(f"the station's area is {cls!r} at the end of the tour, not a corridor")
        station.passed = station.failure is None
    return out
