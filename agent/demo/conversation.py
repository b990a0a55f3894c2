"""The demo's window on the bus: what the tutor says, what the robot answers, where both are.

:class:`Conversation` joins the robot's bus (an embedded Zenoh peer), publishes the tutor's
lines on ``loci/<r>/dialogue/heard`` as a speech recogniser would, and the tutor's walks on
``loci/<r>/sim/tutor``; it listens to the intents the dialogue process sends, the robot's
replies (``dialogue/say``) and questions (``dialogue/ask``), the simulator's true pose
(``sim/truth``) and the tutor's state. Everything heard is kept in order (:attr:`events`)
and printed as it happens through ``echo``. The ``wait_*`` coroutines wait for what the
story needs, with a timeout (None when it did not come).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh

from agent.bus.bridge import BusClosed, Subscription, subscribe_stream
from agent.bus.codecs import codec_for
from agent.bus.keys import state_key, stream_key
from agent.bus.queryable import query_state
from agent.demo import messages

__all__ = ["Conversation", "Event"]

T = TypeVar("T")


@dataclass
class Event:
    """One thing said or heard: ``kind`` is ``tutor``, ``intent``, ``say`` or ``ask``, or
    ``localization`` (the agent's confidence in its pose changed: ``loci.localization/1``);
    ``t`` seconds since the conversation started."""

    kind: str
    t: float
    message: dict[str, Any]
    text: str = ""


@dataclass
class _Latest:
    truth: dict[str, Any] | None = None
    tutor: dict[str, Any] | None = None
    truth_count: int = 0
    path: list[tuple[float, float]] = field(default_factory=list)


def _localization_text(msg: dict[str, Any], before: str | None) -> str:
    """A line for the screen when the confidence changes state (events within a state are not shown)."""
    state = msg.get("state")
    if state == before:
        return ""
    if state == "tracking":
        return "(localization: I know where I am again)" if before is not None else ""
    return f"(localization: {state}, the pose may be {float(msg.get('sigma') or 0.0):.2f} m off)"


class Conversation:
    """The tutor's side of the bus (see the module docstring).

    Args:
        session: an open Zenoh session that reaches the agent, the dialogue and the simulator.
        robot: the robot's name.
        echo: called with each line to show (tutor lines, robot replies and questions).
    """

    def __init__(
        self, session: zenoh.Session, robot: str, echo: Callable[[Event], None] | None = None
    ) -> None:
        self.session = session
        self.robot = robot
        self.echo = echo
        self.events: list[Event] = []
        self.t0 = time.monotonic()
        self.latest = _Latest()
        self._changed = asyncio.Event()
        self._codec = codec_for("loci.utterance/1")
        self._heard = session.declare_publisher(
            stream_key(robot, "dialogue/heard"),
            encoding=zenoh.Encoding(self._codec.zenoh_encoding),
            congestion_control=zenoh.CongestionControl.BLOCK,
        )
        self._tutor = session.declare_publisher(
            messages.tutor_cmd_key(robot),
            encoding=zenoh.Encoding(messages.ENCODING),
            congestion_control=zenoh.CongestionControl.BLOCK,
        )
        self._tutor_sub = session.declare_subscriber(messages.tutor_state_key(robot), self._on_tutor)
        self._subs: list[Subscription[Any]] = [
            subscribe_stream(session, robot, "dialogue/intent"),
            subscribe_stream(session, robot, "dialogue/say"),
            subscribe_stream(session, robot, "dialogue/ask"),
            subscribe_stream(session, robot, "sim/truth", capacity=8),
            subscribe_stream(session, robot, "localization/status"),
        ]
        self._tasks: list[asyncio.Task[None]] = []
        self._loop = asyncio.get_running_loop()

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        kinds = ("intent", "say", "ask", "truth", "localization")
        self._tasks = [asyncio.create_task(self._pump(s, k)) for s, k in zip(self._subs, kinds, strict=True)]

    async def close(self) -> None:
        for s in self._subs:
            s.close()
        for t in self._tasks:
            t.cancel()
        for t in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await t
        with contextlib.suppress(zenoh.ZError):
            self._tutor_sub.undeclare()
            self._heard.undeclare()
            self._tutor.undeclare()

    def elapsed(self) -> float:
        return time.monotonic() - self.t0

    # ------------------------------------------------------------------ input
    def _on_tutor(self, sample: zenoh.Sample) -> None:
        try:
            msg = messages.decode(sample.payload.to_bytes())
        except ValueError:
            return
        self.latest.tutor = msg
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._changed.set)

    async def _pump(self, sub: Subscription[Any], kind: str) -> None:
        with contextlib.suppress(BusClosed):
            while True:
                for msg in await sub.recv_batch(64):
                    if kind == "truth":
                        self.latest.truth = msg
                        self.latest.truth_count += 1
                        xy = (float(msg["x"]), float(msg["y"]))
                        p = self.latest.path
                        if not p or abs(p[-1][0] - xy[0]) + abs(p[-1][1] - xy[1]) > 0.05:
                            p.append(xy)
                    elif kind == "localization":
                        before = next(
                            (e.message.get("state") for e in reversed(self.events) if e.kind == kind), None
                        )
                        self._add(Event(kind, self.elapsed(), msg, _localization_text(msg, before)))
                    else:
                        self._add(Event(kind, self.elapsed(), msg, str(msg.get("text", ""))))
                self._changed.set()

    def _add(self, event: Event) -> None:
        self.events.append(event)
        if self.echo is not None and event.kind != "intent" and event.text:
            self.echo(event)

    def localization(self) -> list[dict[str, Any]]:
        """The agent's localization reports so far: ``t``, state, σ and event of each."""
        return [
            {
                "t": round(e.t, 2),
                "state": e.message.get("state"),
                "sigma": e.message.get("sigma"),
                "event": e.message.get("event"),
                "deviation": e.message.get("deviation"),
            }
            for e in self.events
            if e.kind == "localization"
        ]

    # ------------------------------------------------------------------ output
    async def wait_listener(self, timeout: float) -> bool:
        """Wait until something (the dialogue process) subscribes to ``dialogue/heard``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            status: Any = self._heard.matching_status
            if bool(getattr(status, "matching", status)):
                await asyncio.sleep(1.0)  # a match may precede delivery by a moment
                return True
            await asyncio.sleep(0.05)
        return False

    def say(self, text: str, speaker: str = "tutor") -> int:
        """Publish what the tutor says; returns the index of its event."""
        msg = {
            "schema": "loci.utterance/1",
            "text": text,
            "speaker": speaker,
            "stamp": time.time(),
            "source": "demo",
        }
        self._heard.put(self._codec.encode(msg))
        self._add(Event("tutor", self.elapsed(), msg, text))
        return len(self.events) - 1

    def walk(self, walk: str | list[tuple[float, float]]) -> None:
        """Tell the simulated tutor to walk a leg (by name) or waypoints (queued after its walk)."""
        self._tutor.put(messages.encode(messages.walk_cmd(walk)))

    def stop_tutor(self) -> None:
        self._tutor.put(messages.encode({"schema": messages.TUTOR_CMD, "stop": True}))

    def query(self, name: str, timeout: float = 3.0) -> dict[str, Any] | None:
        """The agent's ``state/<name>`` (graph, areas, place, concepts), or None (blocks)."""
        for reply in query_state(self.session, state_key(self.robot, name), timeout=timeout):
            if reply.value is not None:
                return reply.value
        return None

    async def aquery(self, name: str, timeout: float = 3.0) -> dict[str, Any] | None:
        """:meth:`query` off the event loop."""
        return await asyncio.to_thread(self.query, name, timeout)

    # ------------------------------------------------------------------ waiting
    async def wait_until_async(
        self, predicate: Callable[[Conversation], Awaitable[T | None]], timeout: float, period: float = 0.5
    ) -> T | None:
        """The first truthy result of the coroutine ``predicate(self)``, polled every ``period``
        seconds, or None after ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while True:
            value = await predicate(self)
            if value:
                return value
            if time.monotonic() >= deadline:
                return None
            await asyncio.sleep(period)

    async def wait_until(self, predicate: Callable[[], Any], timeout: float) -> Any:
        """The first true value of ``predicate()`` (checked on every change, and every 0.2 s),
        or None after ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while True:
            value = predicate()
            if value:
                return value
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._changed.wait(), min(left, 0.2))

    def find(self, kind: str, since: int = 0, **match: Any) -> Event | None:
        """The first event of ``kind`` from index ``since`` whose message has ``match``'s values."""
        for e in self.events[since:]:
            if e.kind == kind and all(e.message.get(k) == v for k, v in match.items()):
                return e
        return None

    async def wait_intent(self, since: int, text: str, timeout: float) -> Event | None:
        """The intent the dialogue process sent for the line ``text`` said at ``since``."""
        norm = " ".join(text.split())
        return await self.wait_until(
            lambda: next(
                (
                    e
                    for e in self.events[since:]
                    if e.kind == "intent" and " ".join(str(e.message.get("text", "")).split()) == norm
                ),
                None,
            ),
            timeout,
        )

    async def wait_reply(self, intent_id: str, timeout: float) -> Event | None:
        return await self.wait_until(lambda: self.find("say", in_reply_to=intent_id), timeout)

    async def wait_task(
        self, intent_id: str, timeout: float, pred: Callable[[Event], bool] | None = None
    ) -> Event | None:
        """A later report on the task the intent started (``task`` = its id)."""

        def found() -> Event | None:
            for e in self.events:
                if e.kind == "say" and e.message.get("task") == intent_id and (pred is None or pred(e)):
                    return e
            return None

        return await self.wait_until(found, timeout)

    def truth_xy(self) -> tuple[float, float] | None:
        t = self.latest.truth
        return None if t is None else (float(t["x"]), float(t["y"]))

    def odom_xy(self) -> tuple[float, float] | None:
        t = self.latest.truth
        if t is None or not isinstance(t.get("odom"), Mapping):
            return None
        return (float(t["odom"]["x"]), float(t["odom"]["y"]))
