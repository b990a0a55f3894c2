"""The dialogue process: utterances in, ``loci.intent/1`` out, the robot's replies spoken.

:class:`Dialogue` joins one robot's dialogue streams on an open Zenoh session:

- an utterance (console line, script line, or ``loci.utterance/1`` on ``dialogue/heard``) is
  parsed by :mod:`agent.dialogue.grammar`; not understood → the process itself says "Sorry,
  I did not understand ..."; understood → a ``loci.intent/1`` with a fresh id goes to
  ``dialogue/intent``;
- every intent waits for its reply: the first ``loci.say/1`` (or ``loci.ask/1``) whose
  ``in_reply_to`` is its id. The reply is rendered from its ``content`` with
  :mod:`knowledge.conceptual.referring` (the agent's ``text`` when there is no content or the
  status is ``error``), printed and spoken. No reply within ``reply_timeout`` seconds is
  reported (printed, logged, in the transcript); a reply arriving later is still spoken;
- later reports on a task (``task`` = an intent id, e.g. "I have reached the kitchen.") and
  remarks are spoken too;
- a question (``loci.ask/1``) is spoken with its choices and stays open: the next utterance
  that answers it becomes an ``answer`` intent naming the question's id.

Malformed ``say``/``ask``/``heard`` messages are dropped by the bus bridge, logged and counted
(:meth:`Dialogue.counts`), never raised. :func:`run_dialogue` is the program behind
``loci dialogue``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import signal
import sys
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Awaitable, Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import zenoh

from agent.bus.bridge import BusStats, Publisher, Subscription, publish_stream, subscribe_stream
from agent.bus.keys import robot_name, stream_key
from agent.bus.ready import declare_ready
from agent.bus.session import BusConfig
from agent.dialogue.grammar import NotUnderstood, parse
from agent.dialogue.speech import Speech
from agent.dialogue.transcript import DIALOGUE, ROBOT, Transcript
from knowledge.conceptual.referring import answer_text
from knowledge.errors import ProtocolError

log = logging.getLogger(__name__)

#: Seconds an intent waits for its reply before the silence is reported.
DEFAULT_REPLY_TIMEOUT = 10.0
#: How many sent intents are remembered (to render late replies and task reports).
_REMEMBER = 256
_SPEAKER_PREFIX = re.compile(r"([A-Za-z][A-Za-z0-9_-]{0,30}):\s+(.+)")


@dataclass
class _Sent:
    """An intent this process sent, and what became of it."""

    id: str
    kind: str
    text: str
    args: dict[str, Any]
    sent: float
    reply: asyncio.Future[dict[str, Any] | None]
    timer: asyncio.TimerHandle | None = None
    tasks: list[dict[str, Any]] = field(default_factory=list)


def render_reply(message: Mapping[str, Any], kind: str | None, args: Mapping[str, Any] | None = None) -> str:
    """The sentence to say for a ``loci.say/1``: its ``content`` rendered for ``kind``, else its ``text``.

    ``args`` (the intent's) fill in what a task report leaves out ("I have reached *the
    kitchen*"). A refusal (status ``error``) says the agent's text, or its reason.
    """
    text = str(message.get("text") or "").strip()
    if message.get("status") == "error":
        reason = message.get("reason")
        return text or (
            f"I cannot do that: {reason}" if isinstance(reason, str) and reason else "I cannot do that."
        )
    content = message.get("content")
    if kind and isinstance(content, Mapping) and content:
        merged = dict(content)
        if args and "target" in args and "target" not in merged:
            merged["target"] = args["target"]
        try:
            rendered = answer_text(kind, merged)
        except Exception:  # a content this version does not know how to read: say the agent's text
            log.exception("cannot render the content of a %s reply: %r", kind, content)
            rendered = ""
        if rendered:
            return rendered
    return text


class Dialogue:
    """One robot's dialogue on an open Zenoh session (see the module docstring).

    Args:
        session: an open Zenoh session that reaches the agent.
        robot: the robot's name (the second chunk of its keys).
        speaker: who speaks on the console and in scripts (``"tutor"``).
        listen_heard: also take utterances from ``loci/<robot>/dialogue/heard``.
        reply_timeout: seconds an intent waits for its reply before the silence is reported.
        transcript: where every line goes (memory only if None).
        speech: the synthesiser (None: print only).
        out: where lines are printed (None: nowhere).
        place_words: more nouns the grammar takes as place types.

    Use ``async with Dialogue(...) as d:`` (or :meth:`start` / :meth:`close`) in the event loop.
    """

    def __init__(
        self,
        session: zenoh.Session,
        robot: str,
        *,
        speaker: str = "tutor",
        listen_heard: bool = True,
        reply_timeout: float = DEFAULT_REPLY_TIMEOUT,
        transcript: Transcript | None = None,
        speech: Speech | None = None,
        out: TextIO | None = None,
        place_words: Sequence[str] = (),
    ) -> None:
        if not reply_timeout > 0:
            raise ValueError(f"reply_timeout must be > 0 seconds, got {reply_timeout}")
        if not speaker.strip() or len(speaker) > 128:
            raise ValueError(f"speaker must be a name of 1-128 characters, got {speaker!r}")
        self.session = session
        self.robot = robot_name(robot)
        self.speaker = speaker
        self.listen_heard = listen_heard
        self.reply_timeout = reply_timeout
        self.transcript = transcript or Transcript()
        self.speech = speech
        self.out = out
        self.place_words = tuple(w.lower() for w in place_words)
        self.stats = BusStats()
        self.question: dict[str, Any] | None = None
        self._prefix = f"dlg-{uuid.uuid4().hex[:8]}"
        self._next = 0
        self._sent: OrderedDict[str, _Sent] = OrderedDict()
        self._counts = dict.fromkeys(
            (
                "utterances",
                "intents",
                "not_understood",
                "replies",
                "late",
                "timeouts",
                "questions",
                "answers",
                "reports",
            ),
            0,
        )
        self._activity: asyncio.Condition | None = None
        self._subs: list[Subscription[Any]] = []
        self._pumps: list[asyncio.Task[None]] = []
        self._intents: Publisher[Any] | None = None

    # ---- life cycle -------------------------------------------------------------------------

    async def start(self) -> Dialogue:
        """Declare the subscribers and the publisher, start speaking."""
        self._activity = asyncio.Condition()
        self._intents = publish_stream(self.session, self.robot, "dialogue/intent", stats=self.stats)
        streams: list[tuple[str, Callable[[dict[str, Any]], Awaitable[None]]]] = [
            ("dialogue/say", self._on_say),
            ("dialogue/ask", self._on_ask),
        ]
        if self.listen_heard:
            streams.append(("dialogue/heard", self._on_heard))
        for stream, handler in streams:
            sub = subscribe_stream(self.session, self.robot, stream, stats=self.stats)
            self._subs.append(sub)
            self._pumps.append(asyncio.create_task(self._pump(sub, handler), name=f"dialogue {stream}"))
        if self.speech is not None:
            self.speech.start()
        return self

    async def close(self) -> None:
        """Stop listening, cancel the reply timers, let the last line be spoken (bounded)."""
        for sub in self._subs:
            sub.close()
        for task in self._pumps:
            task.cancel()
        for task in self._pumps:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._pumps.clear()
        self._subs.clear()
        for sent in self._sent.values():
            if sent.timer is not None:
                sent.timer.cancel()
            if not sent.reply.done():
                sent.reply.set_result(None)
        if self._intents is not None:
            self._intents.close()
            self._intents = None
        if self.speech is not None:
            await self.speech.close()

    async def __aenter__(self) -> Dialogue:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def _pump(
        self, sub: Subscription[Any], handler: Callable[[dict[str, Any]], Awaitable[None]]
    ) -> None:
        async for message in sub:
            try:
                await handler(message)
            except Exception:  # one bad message must not end the dialogue
                log.exception("%s: handling a message failed: %r", sub.key, message)
            await self._notify()

    async def _notify(self) -> None:
        assert self._activity is not None
        async with self._activity:
            self._activity.notify_all()

    async def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait until ``predicate()`` holds after some message arrived (True) or ``timeout`` passes (False)."""
        assert self._activity is not None, "call start() first"
        with contextlib.suppress(TimeoutError):
            async with self._activity:
                await asyncio.wait_for(self._activity.wait_for(predicate), timeout)
        return predicate()

    # ---- counters ---------------------------------------------------------------------------

    def counts(self) -> dict[str, int]:
        """Utterances, intents, not understood, replies, late replies, timeouts, questions, answers,
        task reports, and the bus's ``invalid_*`` / ``dropped_*`` counts of say, ask and heard."""
        out = dict(self._counts)
        for name, st in self.stats.snapshot().items():
            short = name.rsplit("/", 1)[-1]
            if name != "dialogue/intent":
                out[f"invalid_{short}"] = st["invalid"]
                out[f"dropped_{short}"] = st["dropped"]
        return out

    @property
    def waiting(self) -> list[str]:
        """Ids of intents still waiting for their reply."""
        return [s.id for s in self._sent.values() if not s.reply.done()]

    # ---- lines ------------------------------------------------------------------------------

    def _print(self, line: str) -> None:
        if self.out is not None:
            print(line, file=self.out, flush=True)

    def _robot_says(self, text: str, kind: str = "say", **extra: Any) -> None:
        if not text:
            return
        self.transcript.add(ROBOT, kind, text, **extra)
        self._print(f"robot: {text}")
        if self.speech is not None:
            self.speech.say(text)

    def _note(self, kind: str, text: str, **extra: Any) -> None:
        self.transcript.add(DIALOGUE, kind, text, **extra)
        self._print(f"({text})")

    # ---- utterances → intents ---------------------------------------------------------------

    async def hear(self, text: str, *, speaker: str | None = None, source: str = "console") -> str | None:
        """Understand one utterance and send its intent.

        Returns:
            The intent's id, or None when it was not understood (the process said sorry) or empty.
        """
        text = " ".join(text.split())
        if not text:
            return None
        who = speaker or self.speaker
        self._counts["utterances"] += 1
        self.transcript.add(who, "utterance", text, source=source)
        if source != "console":
            self._print(f"{who}: {text}")
        choices = self.question["choices"] if self.question else None
        result = parse(text, choices=choices, place_words=self.place_words)
        if isinstance(result, NotUnderstood):
            self._counts["not_understood"] += 1
            log.info("not understood (%s): %r", result.reason, text)
            self._robot_says(f'Sorry, I did not understand "{text}".', "sorry")
            return None
        args = dict(result.args)
        if result.intent == "answer" and self.question is not None:
            args["question"] = self.question["id"]
        return self._send(result.intent, args, text, who)

    def _send(self, kind: str, args: dict[str, Any], text: str, speaker: str) -> str | None:
        assert self._intents is not None, "call start() first"
        self._next += 1
        intent_id = f"{self._prefix}-{self._next}"
        message = {
            "schema": "loci.intent/1",
            "id": intent_id,
            "speaker": speaker,
            "intent": kind,
            "args": args,
            "stamp": time.time(),
            "text": text,
        }
        try:
            self._intents.put(message)
        except (ProtocolError, ValueError) as exc:
            self._counts["not_understood"] += 1
            log.warning("cannot send %r as an intent: %s", text, exc)
            self._robot_says(f'Sorry, I did not understand "{text}".', "sorry")
            return None
        loop = asyncio.get_running_loop()
        sent = _Sent(intent_id, kind, text, args, time.monotonic(), loop.create_future())
        sent.timer = loop.call_later(self.reply_timeout, self._timed_out, intent_id)
        self._sent[intent_id] = sent
        while len(self._sent) > _REMEMBER:
            _, old = self._sent.popitem(last=False)
            if old.timer is not None:
                old.timer.cancel()
            if not old.reply.done():
                old.reply.set_result(None)
        self._counts["intents"] += 1
        if kind == "answer":
            self._counts["answers"] += 1
            self.question = None
        self.transcript.add(DIALOGUE, "intent", kind, id=intent_id, args=args, speaker_of=speaker)
        log.info("intent %s %s %s", intent_id, kind, args)
        return intent_id

    def _timed_out(self, intent_id: str) -> None:
        sent = self._sent.get(intent_id)
        if sent is None or sent.reply.done():
            return
        sent.reply.set_result(None)
        self._counts["timeouts"] += 1
        log.info("no reply to intent %s (%r) within %.1f s", intent_id, sent.text, self.reply_timeout)
        self._note(
            "timeout",
            f'no reply from the robot to "{sent.text}" within {self.reply_timeout:g} s',
            id=intent_id,
            intent=sent.kind,
        )

    async def wait_reply(self, intent_id: str) -> dict[str, Any] | None:
        """The reply to an intent sent by :meth:`hear`: the ``say``/``ask`` message, or None on timeout."""
        sent = self._sent.get(intent_id)
        if sent is None:
            return None
        return await asyncio.shield(sent.reply)

    # ---- the agent's messages ---------------------------------------------------------------

    def _claim_reply(self, message: Mapping[str, Any]) -> tuple[_Sent | None, bool]:
        """The intent a message replies to (if this process sent it) and whether it came too late."""
        sent = self._sent.get(str(message.get("in_reply_to") or ""))
        if sent is None:
            return None, False
        if sent.reply.done():
            return sent, True
        if sent.timer is not None:
            sent.timer.cancel()
        sent.reply.set_result(dict(message))
        self._counts["replies"] += 1
        return sent, False

    async def _on_say(self, message: dict[str, Any]) -> None:
        sent, late = self._claim_reply(message)
        task = self._sent.get(str(message.get("task") or ""))
        if sent is None and task is not None:
            task.tasks.append(message)
            self._counts["reports"] += 1
        about = sent or task
        kind = about.kind if about else message.get("intent")
        args = about.args if about else None
        text = render_reply(message, kind if isinstance(kind, str) else None, args)
        extra: dict[str, Any] = {"status": message.get("status", "ok")}
        if message.get("in_reply_to"):
            extra["in_reply_to"] = message["in_reply_to"]
        if message.get("task"):
            extra["task"] = message["task"]
        if late:
            self._counts["late"] += 1
            extra["late"] = True
        self._robot_says(text, "say", **extra)

    async def _on_ask(self, message: dict[str, Any]) -> None:
        sent, late = self._claim_reply(message)
        if late:
            self._counts["late"] += 1
        self._counts["questions"] += 1
        self.question = {"id": message["id"], "choices": list(message["choices"]), "text": message["text"]}
        choices = [str(c) for c in message["choices"]]
        self._robot_says(str(message["text"]), "ask", id=message["id"], choices=choices)
        if self.out is not None and [c.lower() for c in choices] != ["yes", "no"]:
            self._print(f"  (answer {' / '.join(choices)})")
        del sent

    async def _on_heard(self, message: dict[str, Any]) -> None:
        speaker = message.get("speaker")
        await self.hear(
            str(message["text"]),
            speaker=speaker if isinstance(speaker, str) and speaker.strip() else None,
            source=str(message.get("source") or "heard"),
        )

    # ---- scripts ----------------------------------------------------------------------------

    async def run_script(self, lines: Iterable[str], *, wait: bool = True, pause: float = 0.0) -> int:
        """Say a tutor's script, line by line; returns how many replies did not come in time.

        Each line is an utterance, optionally ``NAME: text`` (another speaker). Blank lines and
        ``#`` comments are skipped. Directives: ``@sleep S`` (wait S seconds), ``@wait-task [S]``
        (wait for a report on the last intent's task, e.g. a go_to reached; default 60 s),
        ``@wait-ask [S]`` (wait until the robot asks a question; default 60 s).

        Args:
            wait: wait for each line's reply (at most ``reply_timeout``) before the next line.
            pause: seconds between lines (after the reply).
        """
        missing = 0
        last: str | None = None
        for number, raw in enumerate(lines, 1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            if line.startswith("@"):
                await self._directive(line, number, last)
                continue
            speaker = None
            m = _SPEAKER_PREFIX.fullmatch(line)
            if m:
                speaker, line = m[1], m[2]
            intent_id = await self.hear(line, speaker=speaker, source="script")
            if intent_id is not None:
                last = intent_id
                if wait and await self.wait_reply(intent_id) is None:
                    missing += 1
            if pause > 0:
                await asyncio.sleep(pause)
        return missing

    async def _directive(self, line: str, number: int, last: str | None) -> None:
        word, _, rest = line.partition(" ")
        try:
            seconds = float(rest) if rest.strip() else None
        except ValueError:
            raise ValueError(
                f"script line {number}: {line!r}: the argument must be seconds, e.g. '@sleep 2'"
            ) from None
        if seconds is not None and not seconds >= 0:
            raise ValueError(f"script line {number}: {line!r}: seconds must be >= 0")
        if word == "@sleep":
            await asyncio.sleep(seconds or 0.0)
        elif word == "@wait-task":
            sent = self._sent.get(last or "")
            if sent is None:
                raise ValueError(f"script line {number}: '@wait-task' needs an intent before it")
            if not await self.wait_for(lambda: bool(sent.tasks), 60.0 if seconds is None else seconds):
                self._note("timeout", f'no report on the task of "{sent.text}"', id=sent.id)
        elif word == "@wait-ask":
            if not await self.wait_for(
                lambda: self.question is not None, 60.0 if seconds is None else seconds
            ):
                self._note("timeout", "the robot asked nothing")
        else:
            raise ValueError(
                f"script line {number}: unknown directive {word!r} (known: @sleep S, @wait-task [S], @wait-ask [S])"
            )

    async def wait_for_agent(self, timeout: float, grace: float = 0.2) -> bool:
        """Wait until a subscriber of ``dialogue/intent`` (the agent) is reachable; False after ``timeout``.

        Zenoh may report a match a moment before samples really reach the new subscriber (see
        :mod:`agent.bus.testing`), so a short ``grace`` follows the match.
        """
        probe = self.session.declare_publisher(stream_key(self.robot, "dialogue/intent"))
        try:
            loop = asyncio.get_running_loop()
            deadline = loop.time() + timeout
            while not _matching(probe):
                if loop.time() >= deadline:
                    return False
                await asyncio.sleep(0.02)
        finally:
            with contextlib.suppress(zenoh.ZError):
                probe.undeclare()
        await asyncio.sleep(grace)
        return True

    async def settle(self, timeout: float | None = None) -> None:
        """Wait until every intent sent has its reply or timed out (at most ``timeout`` seconds)."""
        pending = [s.reply for s in self._sent.values() if not s.reply.done()]
        if pending:
            await asyncio.wait([asyncio.shield(p) for p in pending], timeout=timeout)


def _matching(publisher: zenoh.Publisher) -> bool:
    status: Any = publisher.matching_status  # a MatchingStatus at run time; the stubs say bool
    return bool(getattr(status, "matching", status))


# ---- the program --------------------------------------------------------------------------------


@dataclass(frozen=True)
class DialogueConfig:
    """What ``loci dialogue`` was asked to do.

    Attributes:
        robot: the robot's name (None: this host's).
        bus: the Zenoh session's configuration.
        console: read utterances from standard input.
        heard: take utterances from ``dialogue/heard``.
        script: a file of tutor lines to say (then exit).
        wait: in a script, wait for each line's reply before the next.
        pause: seconds between script lines.
        transcript: the transcript file (None: none).
        speech: speak through espeak-ng when installed.
        voice: espeak-ng's voice.
        reply_timeout: seconds to wait for a reply.
        speaker: the console's and script's speaker name.
        connect_wait: seconds to wait for the agent's intent subscriber before the first line.
    """

    robot: str | None = None
    bus: BusConfig = field(default_factory=BusConfig)
    console: bool = True
    heard: bool = True
    script: Path | None = None
    wait: bool = True
    pause: float = 0.0
    transcript: Path | None = None
    speech: bool = True
    voice: str | None = None
    reply_timeout: float = DEFAULT_REPLY_TIMEOUT
    speaker: str = "tutor"
    connect_wait: float = 5.0


def _stdin_lines(loop: asyncio.AbstractEventLoop, queue: asyncio.Queue[str | None], stream: TextIO) -> None:
    """Read lines on a daemon thread (stdin has no portable asyncio reader); None marks the end."""

    def reader() -> None:
        try:
            for line in stream:
                loop.call_soon_threadsafe(queue.put_nowait, line)
        except (OSError, ValueError):
            pass
        finally:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(queue.put_nowait, None)

    threading.Thread(target=reader, name="dialogue stdin", daemon=True).start()


async def run_dialogue(
    config: DialogueConfig,
    *,
    stdin: TextIO | None = None,
    out: TextIO | None = None,
    stop: asyncio.Event | None = None,
) -> int:
    """The ``loci dialogue`` program: returns 0, or 1 when script lines went unanswered.

    Runs until the script ends, standard input ends (console only), ``stop`` is set, or
    SIGINT/SIGTERM; then waits (at most ``reply_timeout``) for the last replies.
    """
    from agent.bus.session import bus_session

    if config.script is not None:
        try:
            lines = config.script.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise OSError(f"cannot read the script {config.script}: {exc}") from exc
    out = out if out is not None else sys.stdout
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    signals: list[signal.Signals] = []
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
            signals.append(sig)
    speech = Speech(voice=config.voice, enabled=config.speech)
    if config.speech and not speech.available:
        print("(espeak-ng is not installed: the robot's lines are printed only)", file=sys.stderr)
    missing = 0
    try:
        with Transcript(config.transcript) as transcript, bus_session(config.bus) as session:
            dialogue = Dialogue(
                session,
                robot_name(config.robot),
                speaker=config.speaker,
                listen_heard=config.heard,
                reply_timeout=config.reply_timeout,
                transcript=transcript,
                speech=speech,
                out=out,
            )
            async with dialogue:
                ready = declare_ready(session, dialogue.robot, "dialogue")  # listening now
                if not await dialogue.wait_for_agent(config.connect_wait):
                    print(
                        f"(no agent listens for intents of robot {dialogue.robot!r} at "
                        f"{', '.join(config.bus.connect) or 'any endpoint'} yet; still trying)",
                        file=sys.stderr,
                    )
                inputs: list[asyncio.Task[Any]] = []
                if config.script is not None:
                    inputs.append(
                        asyncio.create_task(dialogue.run_script(lines, wait=config.wait, pause=config.pause))
                    )
                elif config.console:
                    inputs.append(asyncio.create_task(_console(dialogue, stdin or sys.stdin)))
                stopper = asyncio.create_task(stop.wait())
                try:
                    await asyncio.wait([*inputs, stopper], return_when=asyncio.FIRST_COMPLETED)
                finally:
                    for task in inputs:
                        if not task.done():
                            task.cancel()
                    stopper.cancel()
                for task in inputs:
                    if task.done() and not task.cancelled():
                        result = task.result()  # re-raises a bad script directive
                        missing += result if isinstance(result, int) else 0
                if not stop.is_set():
                    await dialogue.settle(config.reply_timeout)
                counts = dialogue.counts()
                with contextlib.suppress(Exception):
                    ready.undeclare()
    finally:
        for sig in signals:
            loop.remove_signal_handler(sig)
    summary = ", ".join(f"{k} {v}" for k, v in counts.items() if v or k in ("intents", "replies"))
    print(f"(dialogue: {summary})", file=sys.stderr)
    return 1 if missing else 0


async def _console(dialogue: Dialogue, stream: TextIO) -> None:
    queue: asyncio.Queue[str | None] = asyncio.Queue()
    _stdin_lines(asyncio.get_running_loop(), queue, stream)
    while (line := await queue.get()) is not None:
        await dialogue.hear(line, source="console")
