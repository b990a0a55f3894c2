"""The agent's side of the dialogue (Sect. 7.4): intents in, replies, questions and base goals out.

:class:`DialogueAgent` holds no socket: it reads the pipeline's map (``graph``, ``areas``)
and a concepts store, and every method returns the messages to publish as
:class:`Outgoing` ``(stream, message)`` pairs, so it is tested without a bus.
:func:`agent.conversation.task.run_dialogue` is the thin bus task around it (in :mod:`agent.runtime`).

Every ``loci.intent/1`` gets exactly one ``loci.say/1`` with ``in_reply_to`` = its id
(status ``ok``, ``accepted`` for a task that goes on, or ``error`` with a ``reason``). Tasks
report later with ``task`` = the intent's id: ``go_to`` when the base says the goal was
reached or failed, ``look_around`` when the turn is over, ``follow_me`` when the person is
lost. Contents (``docs/agent.md``):

- ``ask_place`` → ``{"area": AREA}``; ``ask_where`` → ``{"target", "area": AREA|None, "node"}``;
- ``assert_type``/``assert_name``/``assert_object`` → ``{"area": AREA}`` (and ``"object"``),
  asserted on the current area (an object: at the current node);
- ``go_to`` → ``{"target", "node", "path", "distance"}``, a ``loci.base_goal/1`` with the
  path's waypoints; later ``{"reached": bool, "node"}``;
- ``look_around`` → accepted, the base turns once (``base/cmd``); camera recognitions
  (:meth:`DialogueAgent.on_detections`) become objects of the current area and node; the
  report is ``{"objects": [{"name", "kind"}], "area": AREA}``;
- ``follow_me`` → accepted; the people of each scan (the pipeline's
  :attr:`~agent.core.pipeline.StepResult.people`) go through follow-me (:meth:`DialogueAgent.on_scan`)
  to goals on ``base/goal``; refused when people detection is off; ``stop`` cancels everything;
- ``answer`` → the open question (``loci.ask/1``).

AREA is ``{"id", "class", "types", "names", "objects", "current"}`` (the pipeline's class,
the concepts' types, names and objects). Targets are resolved against the concepts
snapshot: an object by name or kind ("the television") → the node it was last seen from;
an area by a name, a type or the class, optionally "with" objects → a node of that area
(:func:`~knowledge.navigation.planning.goal_in_area`), the nearest by path when several fit.

After every change of the map (:meth:`DialogueAgent.tick`), false doorways
(:func:`~knowledge.topology.consistency.false_doorways`) are looked for; a new one is
asked about ("Was there a door here?", choices yes/no, ``about`` = the finding). "no"
removes the doorway node (the areas are recomputed, their events go to the concepts);
"yes" keeps it and it is never asked about again (:attr:`DialogueAgent.confirmed`, saved with
the map). Every reply that acknowledges a fact or a change comes after ``commit`` made it
durable: an agent killed right after its "ok" keeps what it said ok to.

Without the conceptual service (:mod:`agent.conceptual_service`, on with ``[conceptual]``)
:class:`~agent.conversation.memory.MemoryConcepts` keeps what was said and seen in memory,
without reasoning.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import json
import logging
import math
import re
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from agent.bus.schemas import MAX_JSON_DEPTH, SMALL_MESSAGE_BYTES, json_depth
from agent.conversation.memory import AREA_CLASSES, MemoryConcepts, class_of_words
from agent.ratelog import RateLimitedLog
from knowledge.conceptual.lexicon import kind_words
from knowledge.conceptual.referring import answer_text, describe_target
from knowledge.conceptual.referring import with_article as _with_article
from knowledge.errors import LociError
from knowledge.navigation.graph import PLACE, NavigationGraph
from knowledge.navigation.planning import goal_in_area, plan, start_node
from knowledge.topology.areas import (
    AreaEvent,
    AreaMap,
    AreasMerged,
)
from knowledge.topology.consistency import FalseDoorway, false_doorways, remove_doorway

log = logging.getLogger(__name__)
T = TypeVar("T")

#: Turn rate of "look around", rad/s (a full turn takes 2π / this).
LOOK_OMEGA = 0.6
#: Seconds of frame stamps between the frames a look around recognises (every 0.15 rad of the
#: turn): chosen by their stamps, not by how fast the machine gets through them, so a busy
#: computer recognises the same frames, later. An object is recognised in only some of the
#: frames that show it (seen at the edge of the picture, at a slant): every 0.5 s (0.3 rad)
#: the demo's television was missed in 1 of 20 tours, its frames falling between the chosen
#: ones; every 0.25 s each of the 4 Hz camera's frames is recognised (docs/demo.md).
LOOK_FRAME_INTERVAL = 0.25
#: Seconds after the turn a look around waits for the camera's frames before it reports
#: with what it has (a camera that stopped).
LOOK_GRACE = 5.0
#: Seconds "Where are you?" waits for a reasoning that is due (the map changed since the
#: last one: the snapshot's inferred types are those of before the change) before it answers.
REASONING_WAIT = 2.0
YES = frozenset({"yes", "y", "yeah", "yep", "yes there was", "there was", "correct", "right"})
NO = frozenset({"no", "n", "nope", "no there was not", "there was not", "there wasn't", "wrong"})
_ARTICLE = re.compile(r"^(the|a|an|this|that)\s+", re.IGNORECASE)


@dataclass(frozen=True)
class Outgoing:
    """A message to publish: ``stream`` is the key suffix (``"dialogue/say"``, ``"base/goal"``...)."""

    stream: str
    message: dict[str, Any]


class MapState(Protocol):
    """What the dialogue reads of the map (the :class:`~agent.core.pipeline.Pipeline` is one)."""

    graph: NavigationGraph
    areas: AreaMap


class Concepts(Protocol):
    """The conceptual service's interface the dialogue uses (``agent.conceptual_service``)."""

    def snapshot(self) -> dict[str, Any]: ...

    def submit(self, fn: Callable[[Any], T]) -> Awaitable[T]: ...

    def request_reasoning(self) -> Any: ...

    def apply_area_events(self, events: Sequence[AreaEvent], labels: Mapping[int, str | None]) -> Any: ...


# ---------------------------------------------------------------------------- the dialogue


#: the reply's reason to every intent that comes while the agent loads its saved map
STARTING = "starting: the saved map and the conceptual map are still loading"
STARTING_TEXT = "I am just starting and my map is still loading; please say that again in a moment."


def raw_intent_ref(payload: bytes) -> tuple[dict[str, Any], str | None] | None:
    """``({"id", "speaker"}, kind)`` of a raw intent that can be answered (None: it has no
    usable id, or is too large or deep to look into)."""
    if len(payload) > SMALL_MESSAGE_BYTES or json_depth(payload) > MAX_JSON_DEPTH:
        return None
    try:
        doc = json.loads(payload)
    except (ValueError, RecursionError):
        return None
    if not isinstance(doc, dict) or not isinstance(doc.get("id"), str) or len(doc["id"]) > 128:
        return None
    kind = doc.get("intent") if isinstance(doc.get("intent"), str) else None
    speaker = doc.get("speaker") if isinstance(doc.get("speaker"), str) else None
    return {"id": doc["id"], "speaker": speaker}, kind if kind and len(kind) <= 64 else None


def starting_reply(payload: bytes, clock: Callable[[], float] = time.time) -> Outgoing | None:
    """The reply to an intent that came before the agent resumed its map (None: it carries no
    id to reply to): status ``error``, reason :data:`STARTING`, ``content.starting`` true.
    Nothing it asked for was done or taken: the sender says it again once the agent is ready
    (``loci/<robot>/ready/agent``)."""
    ref = raw_intent_ref(payload)
    if ref is None:
        return None
    intent, kind = ref
    msg: dict[str, Any] = {
        "schema": "loci.say/1",
        "stamp": clock(),
        "text": STARTING_TEXT,
        "status": "error",
        "reason": STARTING,
        "in_reply_to": intent["id"],
        "content": {"starting": True},
    }
    if intent["speaker"] is not None:
        msg["to"] = intent["speaker"]
    if kind is not None:
        msg["intent"] = kind
    return Outgoing("dialogue/say", msg)


def _norm(words: str) -> str:
    w = " ".join(words.lower().replace("_", " ").split())
    return _ARTICLE.sub("", w)


def _kind_matches(words: str, kind: str | None) -> bool:
    if not kind:
        return False
    return words in (kind_words(kind), kind.lower()) or words.replace(" ", "") == kind.lower()


@dataclass
class _Resolved:
    """A target resolved: an object (``node`` it was seen from) or candidate areas."""

    kind: str  # "object" | "area"
    areas: list[int]
    node: int | None = None
    name: str | None = None


@dataclass
class _Task:
    intent: str
    kind: str
    speaker: str | None
    target: Any = None
    node: int | None = None


@dataclass
class _Question:
    id: str
    about: dict[str, Any]
    node: int


@dataclass
class _Look:
    """A look around: from ``start`` to ``until`` (the turn), the frames taken from ``next_frame``
    on, every :data:`LOOK_FRAME_INTERVAL` of their stamps; ``handled`` the newest frame stamp
    recognised or passed over (the report waits until a frame from after the turn is)."""

    intent: str
    speaker: str | None
    until: float
    seen: dict[str, dict[str, Any]] = field(default_factory=dict)
    start: float = 0.0
    next_frame: float = 0.0
    handled: float = -math.inf
    frames: int = 0


class DialogueAgent:
    """The agent's dialogue (see the module docstring).

    Args:
        world: the map (``graph``, ``areas``): the running pipeline.
        concepts: the conceptual service (default: a :class:`MemoryConcepts`).
        can_recognise: whether camera recognitions will come (look_around needs them).
        follow_factory: makes a follow-me controller (``agent.core.follow.FollowMe``); None:
            import ``agent.core.follow`` when asked (an error reply if it is not there).
        people: whether the scans come with people (``[people] enabled``); follow-me needs them.
        commit: awaited after each change of the concepts or the map and before the reply
            that acknowledges it (a name, an object, a type, an answer about a door): makes
            the map (graph, areas and :attr:`confirmed`) the change refers to durable (the
            runtime saves ``navgraph.json`` if it changed). The concepts store commits its own
            change in ``submit``.
        on_map_changed: called after the dialogue changed the map, with the edit
            (``{"op": "remove_doorway", "node": 13, "reason": ...}``, a ``loci.map_edit/1`` body
            without its stamps).
        clock: seconds since the epoch.
    """

    def __init__(
        self,
        world: MapState,
        concepts: Concepts | None = None,
        *,
        can_recognise: bool = False,
        follow_factory: Callable[[], Any] | None = None,
        people: bool = True,
        on_map_changed: Callable[[dict[str, Any]], None] | None = None,
        clock: Callable[[], float] = time.time,
        commit: Callable[[], Awaitable[None]] | None = None,
    ) -> None:
        self.world = world
        self.concepts: Concepts = concepts if concepts is not None else MemoryConcepts()
        self.can_recognise = can_recognise
        self._follow_factory = follow_factory
        self.people_on = people
        self._on_map_changed = on_map_changed
        self._commit = commit
        self.clock = clock
        self.pose: tuple[float, float, float] | None = None
        #: how sure the tracked pose is ([localization]; None: tracking off, the odometry is trusted)
        self.confidence: Any = None
        self.tasks: dict[str, _Task] = {}  # base goal id -> task
        self.questions: dict[str, _Question] = {}
        self.confirmed: set[int] = set()  # doorways the tutor confirmed
        self.asked: set[int] = set()
        self.look: _Look | None = None
        self.follow: Any = None
        self._follow_task: _Task | None = None
        self._pending_events: list[AreaEvent] = []
        self._checked_revision = -1
        self._seq = 0
        self.replies = 0
        self.invalid = 0
        self._ratelog = RateLimitedLog(log)

    # ------------------------------------------------------------------ ids, messages
    def _next(self, prefix: str) -> str:
        self._seq += 1
        return f"{prefix}-{self._seq}"

    def say(
        self,
        intent: Mapping[str, Any] | None,
        kind: str | None,
        status: str = "ok",
        content: Mapping[str, Any] | None = None,
        *,
        text: str | None = None,
        reason: str | None = None,
        task: str | None = None,
    ) -> Outgoing:
        """A ``loci.say/1``: a reply to ``intent`` (None: a report on ``task`` or a remark)."""
        body = dict(content or {})
        words = text or (answer_text(kind, body) if kind and status != "error" else "") or reason or "OK."
        msg: dict[str, Any] = {"schema": "loci.say/1", "stamp": self.clock(), "text": words, "status": status}
        if intent is not None:
            msg["in_reply_to"] = intent.get("id")
            if isinstance(intent.get("speaker"), str):
                msg["to"] = intent["speaker"]
        if kind:
            msg["intent"] = kind
        if reason:
            msg["reason"] = reason
        if task:
            msg["task"] = task
        msg["content"] = body
        return Outgoing("dialogue/say", msg)

    def error_for_raw(self, payload: bytes, reason: str) -> Outgoing | None:
        """The error reply to a malformed intent that carries an id (None: it has none)."""
        self.invalid += 1
        ref = raw_intent_ref(payload)
        if ref is None:
            return None
        self.replies += 1
        return self.say(ref[0], ref[1], "error", text="I did not understand that.", reason=reason)

    # ------------------------------------------------------------------ the map
    @property
    def graph(self) -> NavigationGraph:
        return self.world.graph

    @property
    def areas(self) -> AreaMap:
        return self.world.areas

    def current_node(self) -> int | None:
        """The place node the robot is at: the graph's current node, or the nearest place node."""
        g = self.graph
        cur = g.current
        if cur is not None and cur in g and g.node(cur).kind == PLACE:
            return cur
        xy = (
            self.pose[:2]
            if self.pose is not None
            else (g.node(cur).xy if cur is not None and cur in g else None)
        )
        if xy is None:
            return None
        near = g.nearest(xy, kind=PLACE)
        return near[0] if near is not None else None

    def current_area(self) -> int | None:
        node = self.current_node()
        area = self.areas.area_of(node) if node is not None else None
        return area.id if area is not None else None

    def _snapshot(self) -> dict[str, Any]:
        try:
            snap = self.concepts.snapshot()
        except Exception:  # the service may not have reasoned yet
            log.exception("the concepts snapshot failed")
            return {"areas": {}, "objects": {}}
        return snap if isinstance(snap, dict) else {"areas": {}, "objects": {}}

    @staticmethod
    def _objects(snap: Mapping[str, Any]) -> list[dict[str, Any]]:
        """The snapshot's objects as ``{"name", "kind", "area", "node", ...}`` (a map by name or a list)."""
        objs = snap.get("objects") or {}
        pairs = (
            objs.items()
            if isinstance(objs, Mapping)
            else ((None, o) for o in objs)
            if isinstance(objs, list)
            else ()
        )
        return [{**o, "name": o.get("name", name)} for name, o in pairs if isinstance(o, Mapping)]

    @staticmethod
    def _snap_area(snap: Mapping[str, Any], aid: int) -> Mapping[str, Any]:
        areas = snap.get("areas") or {}
        if not isinstance(areas, Mapping):
            return {}
        a = areas.get(str(aid), areas.get(aid))
        return a if isinstance(a, Mapping) else {}

    def area_view(
        self,
        aid: int | None,
        snap: Mapping[str, Any] | None = None,
        extra_objects: Iterable[Mapping[str, Any]] = (),
    ) -> dict[str, Any] | None:
        """The AREA of an area id (None: None)."""
        if aid is None:
            return None
        snap = self._snapshot() if snap is None else snap
        sa = self._snap_area(snap, aid)
        area = self.areas.areas.get(aid)
        label = area.label if area is not None else None
        cls = label if label in AREA_CLASSES else sa.get("class") if sa.get("class") in AREA_CLASSES else None
        objects: list[dict[str, Any]] = []
        seen: set[str] = set()
        for o in [
            *(sa.get("objects") or []),
            *[o for o in self._objects(snap) if o.get("area") == aid],
            *extra_objects,
        ]:
            if isinstance(o, Mapping) and isinstance(o.get("name"), str) and o["name"] not in seen:
                seen.add(o["name"])
                objects.append({"name": o["name"], "kind": o.get("kind")})
        return {
            "id": int(aid),
            "class": cls,
            "types": [t for t in sa.get("types") or [] if isinstance(t, str)],
            "names": [n for n in sa.get("names") or [] if isinstance(n, str)],
            "objects": objects,
            "current": aid == self.current_area(),
        }

    # ------------------------------------------------------------------ targets
    def resolve(self, target: Mapping[str, Any], snap: Mapping[str, Any]) -> _Resolved | None:
        """An object (by name or kind) or the areas a target names (by name, type, class, objects)."""
        head = _norm(str(target.get("head", "")))
        with_ = [_norm(w) for w in target.get("with") or [] if isinstance(w, str)]
        if not head:
            return None
        objs = [
            o
            for o in self._objects(snap)
            if _norm(str(o.get("name", ""))) == head or _kind_matches(head, o.get("kind"))
        ]
        if objs and not with_:
            start = self._start()
            best = None
            for o in objs:
                node = o.get("node")
                if not isinstance(node, int) or node not in self.graph:
                    continue
                p = plan(self.graph, start, node) if start is not None else None
                d = p.distance if p is not None else math.inf
                if best is None or d < best[0]:
                    best = (d, o)
            o = best[1] if best is not None else objs[0]
            area = o.get("area")
            return _Resolved("object", [area] if isinstance(area, int) else [], o.get("node"), o.get("name"))
        found: list[int] = []
        for aid in self.areas.areas:
            view = self.area_view(aid, snap)
            assert view is not None
            names = [_norm(n) for n in view["names"]]
            types = [kind_words(t) for t in view["types"]]
            fits = head in names or head in types or head == view["class"] or head in ("place", "area")
            if fits and with_:
                have = [(_norm(o["name"]), o.get("kind")) for o in view["objects"]]
                fits = all(any(w == n or _kind_matches(w, k) for n, k in have) for w in with_)
            if fits:
                found.append(aid)
        if not found:
            return None
        return _Resolved("area", sorted(found))

    def _start(self) -> int | None:
        return start_node(self.graph, self.pose[:2] if self.pose is not None else None)

    # ------------------------------------------------------------------ intents
    async def handle(self, intent: Mapping[str, Any]) -> list[Outgoing]:
        """The messages answering one (valid) ``loci.intent/1``: exactly one reply on
        ``dialogue/say``, plus base goals and the like."""
        kind = str(intent.get("intent"))
        args = intent.get("args") or {}
        handler = getattr(self, f"_on_{kind}", None)
        self.replies += 1
        if handler is None:
            return [self.say(intent, kind, "error", reason=f"I cannot {kind.replace('_', ' ')} yet.")]
        try:
            out: list[Outgoing] = await handler(intent, args)
        except (LociError, ValueError, KeyError) as exc:
            log.info("intent %s (%s) refused: %s", intent.get("id"), kind, exc)
            return [self.say(intent, kind, "error", reason=str(exc).strip("'\""))]
        except Exception as exc:
            self._ratelog(f"intent {kind}", "intent %s (%s) failed", intent.get("id"), kind, exc=exc)
            return [self.say(intent, kind, "error", reason=f"something went wrong: {exc}")]
        return out

    def _here(self) -> tuple[int, int]:
        node, area = self.current_node(), self.current_area()
        if node is None or area is None:
            raise LociError("I do not know where I am yet; let me drive a little first.")
        return node, area

    async def _tell(self, fn: Callable[[Any], Any]) -> Any:
        """Change the concepts; returns once the change and the map it refers to are durable."""
        result = await self.concepts.submit(fn)
        self.concepts.request_reasoning()
        await self._commit_map()
        return result

    async def _commit_map(self) -> None:
        """Make the map (graph, areas, confirmed doorways) durable: awaited before a reply that
        acknowledges a change of it or a fact about it."""
        if self._commit is not None:
            await self._commit()

    async def _on_ask_place(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        snap = await self._reasoned_snapshot()
        area = self.area_view(self.current_area(), snap)
        return [self.say(intent, "ask_place", "ok", {"area": area, **self._certainty()})]

    def _certainty(self) -> dict[str, Any]:
        """``{"certain": False, "sigma": metres}`` while the tracked pose is not sure ({} else):
        the answer then says "I think ..." (knowledge.conceptual.referring.answer_text)."""
        conf = self.confidence
        if conf is None or getattr(conf, "certain", True):
            return {}
        return {"certain": False, "sigma": round(float(conf.sigma[0]), 2), "localization": conf.state}

    async def _reasoned_snapshot(self) -> dict[str, Any]:
        """The concepts snapshot, after the reasoning that is due if one is (at most
        :data:`REASONING_WAIT` seconds): right after the area changed (a node joined it), the
        cached snapshot has the area without its inferred types until the reasoner has run,
        and "Where are you?" said "the room with the couch and the television" where it had
        just said "the living room"."""
        snap = self._snapshot()
        flush = getattr(self.concepts, "flush", None)
        due = isinstance(snap.get("reasoned"), int) and snap["reasoned"] < int(snap.get("version") or 0)
        if due and flush is not None:
            try:  # shielded: a late answer must not cancel the reasoning itself
                fresh = await asyncio.wait_for(asyncio.shield(flush()), REASONING_WAIT)
            except Exception:  # TimeoutError, or the reasoning failed (the service logs why)
                log.warning(
                    "the reasoner did not finish within %.1f s; answering from the cache", REASONING_WAIT
                )
            else:
                if isinstance(fresh, dict):
                    snap = fresh
        return snap

    async def _on_ask_where(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        target = dict(args["target"])
        snap = self._snapshot()
        res = self.resolve(target, snap)
        content: dict[str, Any] = {"target": target, "area": None, "node": None}
        if res is not None and res.kind == "object":
            content["area"] = self.area_view(res.areas[0], snap) if res.areas else None
            content["node"] = res.node
        elif res is not None:
            start = self._start()
            best = self._nearest_area(res.areas, start) if start is not None else None
            aid = best[0] if best is not None else res.areas[0]
            content["area"] = self.area_view(aid, snap)
        return [self.say(intent, "ask_where", "ok", content)]

    async def _on_assert_type(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        _, area = self._here()
        word, speaker = str(args["type"]), str(intent.get("speaker", "tutor"))
        result = await self._tell(lambda m: m.assert_type(area, word, speaker))
        found = (
            list(getattr(result, "contradictions", ()) or ()) if not getattr(result, "accepted", True) else []
        )
        if not found:
            return [self.say(intent, "assert_type", "ok", {"area": self.area_view(area)})]
        # a contradiction: nothing was changed; ask which is right (Sect. 7.2.4.5)
        c = found[0]
        other = (
            c.word if c.layer == "asserted" and c.word and c.word != word else kind_words(c.conflicts_with)
        )
        if c.layer == "asserted" and c.word is None:
            other = kind_words(c.conflicts_with)
        said = {"asserted": f"{c.speaker or 'someone'} said it is", "acquired": "I thought it was"}.get(
            c.layer, "it looks to me like"
        )
        text = f"You said this is {_a(word)}, but {said} {_a(other)}. Which is it?"
        about = {
            "kind": "contradiction",
            "area": area,
            "word": _norm(word),
            "other": _norm(other),
            "speaker": speaker,
            "contradictions": [x.to_json() for x in found],
        }
        q = _Question(self._next("q-type"), about, -1)
        self.questions[q.id] = q
        ask = {
            "schema": "loci.ask/1",
            "id": q.id,
            "stamp": self.clock(),
            "text": text,
            "choices": [_norm(word), _norm(other)],
            "about": about,
            "in_reply_to": str(intent["id"]),
        }
        content = {"area": self.area_view(area), "contradictions": about["contradictions"]}
        reply = self.say(intent, "assert_type", "ok", content, text=f"Hm, I am not sure it is {_a(word)}.")
        return [reply, Outgoing("dialogue/ask", ask)]

    async def _answer_contradiction(
        self, intent: Mapping[str, Any], q: _Question, answer: str, content: dict[str, Any]
    ) -> list[Outgoing]:
        """The person chose between the new word and the old one for an area's type."""
        about = q.about
        area, word, other = int(about["area"]), str(about["word"]), str(about["other"])
        if answer not in (word, other):
            raise LociError(f"Please say {word} or {other}.")
        del self.questions[q.id]
        if answer == other:
            content["kept"] = other
            return [self.say(intent, "answer", "ok", content, text=f"Thank you, it stays {_a(other)}.")]
        others = sorted(
            {str(c["speaker"]) for c in about["contradictions"] if c["layer"] == "asserted" and c["speaker"]}
        )
        for sp in others:  # what the others said about this area goes; the answer stands
            await self._tell(_retracter(area, sp))
        speaker = str(about["speaker"])
        result = await self._tell(lambda m: m.assert_type(area, word, speaker))
        if getattr(result, "accepted", True):
            content["asserted"] = word
            content["area"] = self.area_view(area)
            return [self.say(intent, "answer", "ok", content, text=f"Thank you, it is {_a(word)}.")]
        content["kept"] = other
        text = f"I still see {_a(other)} here, so I cannot call it {_a(word)}."
        return [self.say(intent, "answer", "ok", content, text=text)]

    async def _on_assert_name(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        _, area = self._here()
        name, speaker = str(args["name"]), str(intent.get("speaker", "tutor"))
        await self._tell(lambda m: m.assert_name(area, name, speaker))
        return [self.say(intent, "assert_name", "ok", {"area": self.area_view(area)})]

    async def _on_assert_object(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        node, area = self._here()
        name = _norm(str(args["object"]))
        kind = class_of_words(name)
        await self._tell(lambda m: m.add_object(name, kind, area, node, source="tutor"))
        obj = {"name": name, "kind": kind}
        view = self.area_view(area, extra_objects=[obj])
        return [self.say(intent, "assert_object", "ok", {"object": obj, "area": view, "node": node})]

    def _nearest_area(self, areas: Sequence[int], start: int) -> tuple[int, int, float] | None:
        """Of candidate areas, ``(area, goal node, metres)`` with the shortest path from ``start``."""
        best: tuple[int, int, float] | None = None
        for aid in areas:
            a = self.areas.areas.get(aid)
            if a is None:
                continue
            goal = goal_in_area(self.graph, start, a.nodes)
            p = plan(self.graph, start, goal) if goal is not None else None
            if p is not None and (best is None or p.distance < best[2]):
                best = (aid, p.goal, p.distance)
        return best

    async def _on_go_to(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        target = dict(args["target"])
        what = describe_target(target)
        res = self.resolve(target, self._snapshot())
        if res is None:
            raise LociError(f"I do not know where {what} is.")
        start = self._start()
        if start is None:
            raise LociError("I do not know where I am yet; let me drive a little first.")
        goal: int | None = res.node if res.kind == "object" and res.node in self.graph else None
        if goal is None:
            best = self._nearest_area(res.areas, start)
            goal = best[1] if best is not None else None
        p = plan(self.graph, start, goal) if goal is not None else None
        if p is None:
            raise LociError(f"I cannot find a way to {what} from here.")
        points = list(p.waypoints)
        if len(points) > 1 and self.pose is not None:
            x0, y0 = points[0]
            if math.hypot(x0 - self.pose[0], y0 - self.pose[1]) <= self.graph.params.reach_radius:
                points = points[1:]
        goal_id = f"goto-{intent['id']}"
        self._cancel_follow()
        self.tasks = {k: t for k, t in self.tasks.items() if t.kind != "go_to"}
        self.tasks[goal_id] = _Task(str(intent["id"]), "go_to", intent.get("speaker"), target, p.goal)
        goal_msg = {
            "schema": "loci.base_goal/1",
            "id": goal_id,
            "stamp": self.clock(),
            "frame_id": "odom",
            "path": [
                {"x": round(x, 4), "y": round(y, 4)} for x, y, _ in (self._to_odom(x, y) for x, y in points)
            ],
        }
        content = {"target": target, "node": p.goal, "path": list(p.nodes), "distance": round(p.distance, 3)}
        return [self.say(intent, "go_to", "accepted", content), Outgoing("base/goal", goal_msg)]

    def _to_odom(self, x: float, y: float, theta: float = 0.0) -> tuple[float, float, float]:
        """A point of the map (the graph's, the tracks' frame) in the odometry frame the base
        drives in: the same unless the pipeline tracks its pose (``[localization]``), whose
        map -> odom correction (the one the latest scan's pose was given) is undone."""
        c = getattr(self.world, "correction", None)
        if c is None:
            return x, y, theta
        from knowledge.localization.se2 import compose, inverse

        o = compose(inverse(c), [x, y, theta])
        return float(o[0]), float(o[1]), float(o[2])

    async def _on_stop(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        stopped = sorted(
            {t.kind for t in self.tasks.values()}
            | ({"follow_me"} if self.follow else set())
            | ({"look_around"} if self.look else set())
        )
        self.tasks.clear()
        self._cancel_follow()
        out = [self.say(intent, "stop", "ok", {"stopped": stopped})]
        if self.look is not None:
            self.look = None
            out.append(self._twist(0.0))
        out.append(
            Outgoing("base/goal", {"schema": "loci.base_goal/1", "stamp": self.clock(), "cancel": True})
        )
        return out

    async def _on_follow_me(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        if self._follow_factory is None:
            try:
                from agent.core.follow import FollowMe
            except ImportError as exc:
                raise LociError(
                    "I cannot follow people: follow-me is not installed (agent.core.follow)."
                ) from exc
            self._follow_factory = FollowMe
        if not self.people_on:
            raise LociError("I cannot follow people: people detection is off ([people] enabled = false).")
        self.tasks = {k: t for k, t in self.tasks.items() if t.kind != "go_to"}
        self.look = None
        self.follow = self._follow_factory()
        self.follow.start(self.clock())
        self._follow_task = _Task(str(intent["id"]), "follow_me", intent.get("speaker"))
        return [self.say(intent, "follow_me", "accepted", {"following": True})]

    def _cancel_follow(self) -> None:
        if self.follow is not None:
            with contextlib.suppress(Exception):
                self.follow.stop()
        self.follow = None
        self._follow_task = None

    async def _on_look_around(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        if not self.can_recognise:
            raise LociError(
                "I cannot recognise objects: there is no object database (teach me with 'loci objects add')."
            )
        self._here()
        self._cancel_follow()
        now = self.clock()
        self.look = _Look(
            str(intent["id"]),
            intent.get("speaker"),
            now + 2 * math.pi / LOOK_OMEGA,
            start=now,
            next_frame=now,
        )
        return [
            self.say(intent, "look_around", "accepted", {}, text="I am looking around."),
            self._twist(LOOK_OMEGA),
        ]

    def _twist(self, omega: float) -> Outgoing:
        return Outgoing(
            "base/cmd", {"schema": "loci.twist/1", "stamp": self.clock(), "v": 0.0, "omega": omega}
        )

    async def _on_answer(self, intent: Mapping[str, Any], args: Mapping[str, Any]) -> list[Outgoing]:
        qid = args.get("question")
        if qid is None and self.questions:
            qid = next(reversed(self.questions))
        q = self.questions.get(qid) if isinstance(qid, str) else None
        if q is None:
            raise LociError("I did not ask anything." if not self.questions else f"I did not ask {qid!r}.")
        answer = _norm(str(args["answer"])).strip(".!")
        content: dict[str, Any] = {"question": q.id, "answer": answer}
        if q.about.get("kind") == "contradiction":
            return await self._answer_contradiction(intent, q, answer, content)
        if answer in YES:
            del self.questions[q.id]
            self.confirmed.add(q.node)
            await self._commit_map()  # the confirmation is saved with the map (never asked again)
            return [self.say(intent, "answer", "ok", content, text="Thank you, I keep the door.")]
        if answer not in NO:
            raise LociError("Please answer yes or no.")
        del self.questions[q.id]
        out: list[Outgoing] = []
        if q.node in self.graph and self.graph.node(q.node).kind != PLACE:
            events = remove_doorway(self.graph, self.areas, q.node)
            self._pending_events.extend(events)
            content["removed"] = q.node
            content["merged"] = [[e.area_id, *e.absorbed] for e in events if isinstance(e, AreasMerged)]
            if self._on_map_changed is not None:
                self._on_map_changed(
                    {
                        "op": "remove_doorway",
                        "node": q.node,
                        "reason": f"{q.id}: {intent.get('text') or answer}",
                    }
                )
        await self._commit_map()  # the map without the door is on disk before the thanks
        content["area"] = self.area_view(self.current_area())
        out.append(
            self.say(intent, "answer", "ok", content, text="Thank you, I removed the door from my map.")
        )
        return out

    # ------------------------------------------------------------------ events from the robot
    def on_area_events(self, events: Sequence[AreaEvent]) -> None:
        """The pipeline's area events (queued; :meth:`tick` hands them to the concepts)."""
        self._pending_events.extend(events)

    async def _hand_over_events(self) -> None:
        if self._pending_events:
            events, self._pending_events = self._pending_events, []
            result = self.concepts.apply_area_events(events, self.areas.labels())
            if inspect.isawaitable(result):
                await result

    async def flush_area_events(self) -> None:
        """Hand the queued area events to the concepts now and return once every change handed
        over so far is committed. The runtime awaits this before it writes the map: the saved
        concepts are never older than the saved map (a kill between the map's save and the
        concepts' could leave names on an area the map merged away)."""
        await self._hand_over_events()
        await self.concepts.submit(lambda m: None)  # after the changes before it (one owner thread)

    def on_base_status(self, status: Mapping[str, Any]) -> list[Outgoing]:
        """A ``loci.base_status/1``: a go-to task reached or failed → its report."""
        goal = status.get("goal")
        state = status.get("status")
        if not isinstance(goal, str) or goal not in self.tasks:
            return []
        if state not in ("reached", "failed", "collided", "cancelled"):
            return []
        task = self.tasks.pop(goal)
        content = {"target": task.target, "reached": state == "reached", "node": task.node}
        if state == "reached":
            # the base reached the goal it was given in its odometry frame; whether that is the
            # target depends on the tracked pose: when it is not sure, the robot says so
            content.update(self._certainty())
            return [self.say(None, task.kind, "ok", content, task=task.intent)]
        reason = status.get("reason") or f"the base says {state}"
        text = f"I could not get to {describe_target(task.target)}: {reason}."
        return [self.say(None, task.kind, "error", content, text=text, reason=str(reason), task=task.intent)]

    def on_pose(self, pose: tuple[float, float, float]) -> None:
        self.pose = pose

    def on_localization(self, confidence: Any) -> None:
        """How sure the tracked pose is now (a :class:`~knowledge.localization.confidence.Confidence`)."""
        self.confidence = confidence

    def on_scan(self, scan: Any, pose: tuple[float, float, float], people: Any = None) -> list[Outgoing]:
        """One processed scan, the laser's odometry pose and the scan's people (a
        :class:`~knowledge.people.pipeline.PeopleFrame` tracked in the odometry frame, or None):
        follow-me goals while following (a scan without people counts as nobody seen)."""
        self.pose = pose
        if self.follow is None:
            return []
        out: list[Outgoing] = []
        step = self.follow.update(people if people is not None else [], pose, float(scan.stamp))
        task = self._follow_task.intent if self._follow_task is not None else None
        message = getattr(step, "message", None)
        if message:
            out.append(self.say(None, "follow_me", "ok", {"state": step.state}, text=message, task=task))
        if getattr(step, "cancel", False):
            out.append(
                Outgoing("base/goal", {"schema": "loci.base_goal/1", "stamp": self.clock(), "cancel": True})
            )
        if step.goal is not None:
            gx, gy, gth = self._to_odom(*(float(v) for v in step.goal))
            goal = {"x": gx, "y": gy, "theta": gth}
            msg = {
                "schema": "loci.base_goal/1",
                "id": self._next("follow"),
                "stamp": self.clock(),
                "frame_id": "odom",
                "goal": goal,
            }
            out.append(Outgoing("base/goal", msg))
        return out

    @property
    def looking(self) -> bool:
        """Whether camera frames should be recognised now."""
        return self.look is not None

    def frame_due(self, stamp: float) -> bool:
        """Whether the camera frame stamped ``stamp`` is one the look around recognises (see
        :data:`LOOK_FRAME_INTERVAL`); a frame passed over counts as handled."""
        look = self.look
        if look is None:
            return False
        if look.start <= stamp <= look.until and stamp >= look.next_frame:
            look.next_frame = stamp + LOOK_FRAME_INTERVAL
            return True
        look.handled = max(look.handled, stamp)
        return False

    def frame_done(self, stamp: float) -> None:
        """The frame stamped ``stamp`` was recognised (or failed to decode)."""
        if self.look is not None:
            self.look.handled = max(self.look.handled, stamp)
            self.look.frames += 1

    async def on_detections(self, detections: Sequence[Any], stamp: float) -> list[Outgoing]:
        """Recognised objects (``name``, ``kind``, ``score``...) in a frame taken at ``stamp``:
        objects of the current area at the current node, published on ``objects``."""
        node, area = self.current_node(), self.current_area()
        recs = []
        for d in detections:
            name = str(getattr(d, "name", ""))
            if not name:
                continue
            kind = getattr(d, "kind", None) or class_of_words(name)
            rec: dict[str, Any] = {
                "name": name,
                "kind": kind,
                "score": float(getattr(d, "score", 0.0)),
                "node": node,
                "area": area,
            }
            inliers = getattr(d, "inliers", None)
            if isinstance(inliers, int) and not isinstance(inliers, bool):
                rec["inliers"] = inliers
            recs.append(rec)
            if area is not None:
                await self._tell(_adder(name, str(kind), area, node))
            if self.look is not None:
                self.look.seen[name] = {"name": name, "kind": kind}
        if not recs:
            return []
        return [
            Outgoing(
                "objects",
                {"schema": "loci.objects/1", "stamp": stamp, "frame_id": "camera", "recognitions": recs},
            )
        ]

    # ------------------------------------------------------------------ periodic
    async def tick(self) -> list[Outgoing]:
        """Hand queued area events to the concepts, end a finished look-around, and ask about
        false doorways after a map change."""
        out: list[Outgoing] = []
        await self._hand_over_events()
        now = self.clock()
        if self.look is not None:
            # the turn is over and every frame of it is recognised (a frame from after it was
            # handled), or the camera has been silent too long
            done = now >= self.look.until and (
                self.look.handled >= self.look.until or now >= self.look.until + LOOK_GRACE
            )
            if done:
                look, self.look = self.look, None
                objects = list(look.seen.values())
                content = {
                    "objects": objects,
                    "area": self.area_view(self.current_area(), extra_objects=objects),
                    "frames": look.frames,
                }
                out.append(self._twist(0.0))
                out.append(self.say(None, "look_around", "ok", content, task=look.intent))
            elif now < self.look.until:
                out.append(self._twist(LOOK_OMEGA))
            else:
                out.append(self._twist(0.0))  # turned: waiting for the last frames' recognition
        out.extend(self.check_consistency())
        return out

    def check_consistency(self) -> list[Outgoing]:
        """A ``loci.ask/1`` about the first new false doorway, if the map changed (one open question at a time)."""
        g = self.graph
        if g.revision == self._checked_revision:
            return []
        self._checked_revision = g.revision
        if self.questions:
            return []
        found: list[FalseDoorway] = false_doorways(g, self.areas, ignore=self.confirmed | self.asked)
        if not found:
            return []
        f = found[0]
        self.asked.add(f.door)
        q = _Question(self._next("q-door"), f.as_dict(), f.door)
        self.questions[q.id] = q
        msg = {
            "schema": "loci.ask/1",
            "id": q.id,
            "stamp": self.clock(),
            "text": "Was there a door here?",
            "choices": ["yes", "no"],
            "about": q.about,
        }
        return [Outgoing("dialogue/ask", msg)]


def _a(words: str) -> str:
    """ "a kitchen", "an office" (a possessive or already determined phrase as it is)."""
    return _with_article(words, definite=False)


def _retracter(area: int, speaker: str) -> Callable[[Any], Any]:
    def retract(m: Any) -> Any:
        return m.retract(area, speaker=speaker)

    return retract


def _adder(name: str, kind: str, area: int, node: int | None) -> Callable[[Any], Any]:
    def add(m: Any) -> Any:
        return m.add_object(name, kind, area, node, source="camera")

    return add
