"""The dialogue process end to end: real Zenoh sessions on loopback, an agent stand-in peer.

The stand-in is a second Zenoh session in the test that answers each ``loci.intent/1`` with
``loci.say/1`` / ``loci.ask/1`` messages (a test peer speaking the protocol, not a mock of
our code). Timeouts are short so the whole file runs in a few seconds.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import threading
from collections.abc import Callable, Coroutine, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import zenoh

from agent.bus.keys import stream_key
from agent.bus.schemas import SCHEMAS
from agent.bus.session import BusConfig, close_session, listening_endpoints, open_session
from agent.bus.testing import session_pair, settle
from agent.commands import dialogue as dialogue_command
from agent.dialogue.process import Dialogue, render_reply
from agent.dialogue.transcript import Transcript, read_transcript
from knowledge.conceptual.referring import describe_area

ROBOT = "rosie"
LIVING = {
    "id": 3,
    "class": "room",
    "types": ["LivingRoom", "Room"],
    "names": [],
    "objects": [{"name": "tv", "kind": "Television"}],
    "current": True,
}


def run(coro: Coroutine[Any, Any, Any], timeout: float = 20.0) -> Any:
    return asyncio.run(asyncio.wait_for(coro, timeout))


Reply = Callable[[dict[str, Any]], list[tuple[str, dict[str, Any] | bytes]]]


def tour_agent(intent: dict[str, Any]) -> list[tuple[str, dict[str, Any] | bytes]]:
    """How the stand-in answers: one or more (stream, message) per intent; stop gets no reply."""
    iid, kind, args = intent["id"], intent["intent"], intent.get("args", {})
    say: dict[str, Any] = {"schema": "loci.say/1", "in_reply_to": iid, "intent": kind, "stamp": 1.0}
    if kind == "ask_place":
        return [("dialogue/say", {**say, "text": "I am in area 3.", "content": {"area": LIVING}})]
    if kind == "go_to":
        content = {"target": args["target"], "node": 4, "path": [1, 2, 4], "distance": 12.4}
        return [
            ("dialogue/say", {**say, "status": "accepted", "text": "Going.", "content": content}),
            (
                "dialogue/say",
                {
                    "schema": "loci.say/1",
                    "task": iid,
                    "text": "Reached.",
                    "content": {"reached": True, "node": 4},
                },
            ),
        ]
    if kind == "look_around":
        return [("dialogue/say", {**say, "text": "I see a television."})]
    if kind == "ask_where":
        return [("dialogue/say", {**say, "status": "error", "text": "", "reason": "I know no couch"})]
    if kind == "assert_type":
        return [
            ("dialogue/say", {**say, "text": "OK."}),
            (
                "dialogue/ask",
                {
                    "schema": "loci.ask/1",
                    "id": "q-7",
                    "text": "Was there a door here?",
                    "choices": ["yes", "no"],
                },
            ),
        ]
    if kind == "answer":
        return [("dialogue/say", {**say, "text": "Thanks."})]
    return []


class AgentPeer:
    """A Zenoh session that receives intents and answers them with ``reply``."""

    def __init__(self, session: zenoh.Session, reply: Reply = tour_agent) -> None:
        self.session = session
        self.reply = reply
        self.intents: list[dict[str, Any]] = []
        self.lock = threading.Lock()
        self._sub = session.declare_subscriber(stream_key(ROBOT, "dialogue/intent"), self._on_intent)

    def put(self, stream: str, message: dict[str, Any] | bytes) -> None:
        if isinstance(message, bytes):
            self.session.put(stream_key(ROBOT, stream), message)
            return
        schema = str(message["schema"])
        payload = SCHEMAS.encode(message, schema)
        self.session.put(
            stream_key(ROBOT, stream), payload, encoding=zenoh.Encoding(f"application/json;{schema}")
        )

    def _on_intent(self, sample: zenoh.Sample) -> None:
        intent = SCHEMAS.decode(sample.payload.to_bytes(), "loci.intent/1")
        with self.lock:
            self.intents.append(intent)
        for stream, message in self.reply(intent):
            self.put(stream, message)

    def kinds(self) -> list[str]:
        with self.lock:
            return [i["intent"] for i in self.intents]


@contextmanager
def connected(reply: Reply = tour_agent) -> Iterator[tuple[AgentPeer, zenoh.Session, zenoh.Session]]:
    with session_pair() as (agent_session, dialogue_session):
        yield AgentPeer(agent_session, reply), agent_session, dialogue_session


def test_a_tour_script_end_to_end(tmp_path: Path) -> None:
    out = io.StringIO()

    async def main() -> tuple[Dialogue, int, AgentPeer]:
        with connected() as (peer, a, b), Transcript(tmp_path / "t.jsonl") as transcript:
            async with Dialogue(b, ROBOT, reply_timeout=0.6, transcript=transcript, out=out) as d:
                settle(a, b)  # the dialogue's say/ask subscribers reached the agent
                settle(b, a)  # the agent's intent subscriber reached the dialogue
                missing = await d.run_script(
                    [
                        "# a short tour",
                        "Where are you?",
                        "Go to the kitchen",
                        "@wait-task 5",
                        "blah blah blah",
                        "Look around",
                        "Where is the couch?",
                        "anna: You are in the corridor",
                        "@wait-ask 5",
                        "yeah, there was",
                        "Stop",
                    ]
                )
                await d.settle(2.0)
            return d, missing, peer

    d, missing, peer = run(main())
    assert peer.kinds() == ["ask_place", "go_to", "look_around", "ask_where", "assert_type", "answer", "stop"]
    answer = peer.intents[5]
    assert answer["args"] == {"answer": "yes", "question": "q-7"}
    assert peer.intents[4]["speaker"] == "anna" and peer.intents[0]["speaker"] == "tutor"
    assert len({i["id"] for i in peer.intents}) == len(peer.intents)
    assert missing == 1  # "Stop" got no reply

    said = [e.text for e in d.transcript.entries if e.speaker == "robot"]
    # content rendered with referring expressions, not the agent's text
    assert f"I am in {describe_area(LIVING)}." in said and "I am in area 3." not in said
    assert "I am going to the kitchen, 12 metres away." in said
    assert "I have reached the kitchen." in said
    assert 'Sorry, I did not understand "blah blah blah".' in said
    assert "I see a television." in said  # no content: the agent's text
    assert "I cannot do that: I know no couch" in said  # refusal without text: its reason
    assert "Was there a door here?" in said
    counts = d.counts()
    assert counts["intents"] == 7 and counts["not_understood"] == 1 and counts["timeouts"] == 1
    assert counts["questions"] == 1 and counts["answers"] == 1 and counts["reports"] == 1
    assert d.question is None

    lines = read_transcript(tmp_path / "t.jsonl")
    timeouts = [e for e in lines if e["kind"] == "timeout"]
    assert len(timeouts) == 1 and "Stop" in timeouts[0]["text"]
    utterances = [e["text"] for e in lines if e["kind"] == "utterance"]
    assert utterances[:3] == ["Where are you?", "Go to the kitchen", "blah blah blah"]
    assert all(isinstance(e["stamp"], float | int) and e["time"] for e in lines)
    stamps = [e["stamp"] for e in lines]
    assert stamps == sorted(stamps)
    assert "robot: I have reached the kitchen." in out.getvalue()


def test_malformed_messages_are_counted_and_the_dialogue_goes_on() -> None:
    def bad_then_good(intent: dict[str, Any]) -> list[tuple[str, dict[str, Any] | bytes]]:
        iid = intent["id"]
        return [
            ("dialogue/say", b"{not json"),
            ("dialogue/say", b'{"schema": "loci.say/1", "in_reply_to": "' + iid.encode() + b'"}'),  # no text
            (
                "dialogue/say",
                b'{"schema": "loci.ask/1", "id": "x", "text": "?", "choices": ["a"]}',
            ),  # wrong schema
            (
                "dialogue/ask",
                b'{"schema": "loci.ask/1", "id": "q", "text": "Which?", "choices": []}',
            ),  # no choices
            ("dialogue/ask", b"\xff\xfe"),
            # well-formed, but content of the wrong shape: rendered from the text
            (
                "dialogue/say",
                {
                    "schema": "loci.say/1",
                    "in_reply_to": iid,
                    "text": "Somewhere.",
                    "content": {"area": [1, 2]},
                },
            ),
        ]

    async def main() -> Dialogue:
        with connected(bad_then_good) as (_, a, b):
            async with Dialogue(b, ROBOT, reply_timeout=3.0) as d:
                settle(a, b)
                settle(b, a)
                intent_id = await d.hear("Where are you?")
                assert intent_id is not None
                reply = await d.wait_reply(intent_id)
                assert reply is not None and reply["text"] == "Somewhere."
                assert await d.wait_for(lambda: d.counts().get("invalid_ask", 0) == 2, 2.0)
            return d

    d = run(main())
    counts = d.counts()
    assert counts["invalid_say"] == 3 and counts["invalid_ask"] == 2
    assert counts["replies"] == 1 and counts["timeouts"] == 0
    assert [e.text for e in d.transcript.entries if e.speaker == "robot"] == ["Somewhere."]


def test_utterances_from_a_recogniser_on_heard() -> None:
    async def main() -> tuple[Dialogue, AgentPeer]:
        with connected() as (peer, a, b):
            async with Dialogue(b, ROBOT, reply_timeout=2.0) as d:
                settle(a, b)
                settle(b, a)
                peer.put(
                    "dialogue/heard",
                    {"schema": "loci.utterance/1", "text": "Where am I?", "speaker": "bob", "source": "vosk"},
                )
                peer.put("dialogue/heard", {"schema": "loci.utterance/1", "text": "Fly to the moon"})
                assert await d.wait_for(
                    lambda: d.counts()["replies"] == 1 and d.counts()["utterances"] == 2, 3
                )
            return d, peer

    d, peer = run(main())
    assert peer.kinds() == ["ask_place"]
    assert peer.intents[0]["speaker"] == "bob"
    heard = [e for e in d.transcript.entries if e.kind == "utterance"]
    assert [(e.speaker, e.extra["source"]) for e in heard] == [("bob", "vosk"), ("tutor", "heard")]
    assert d.counts()["not_understood"] == 1


def test_a_late_reply_is_still_spoken_and_marked() -> None:
    async def main() -> Dialogue:
        with connected(lambda i: []) as (peer, a, b):
            async with Dialogue(b, ROBOT, reply_timeout=0.2) as d:
                settle(a, b)
                settle(b, a)
                intent_id = await d.hear("Look around")
                assert intent_id is not None
                assert await d.wait_reply(intent_id) is None
                peer.put(
                    "dialogue/say",
                    {
                        "schema": "loci.say/1",
                        "in_reply_to": intent_id,
                        "text": "Done.",
                        "content": {"objects": [{"name": "couch", "kind": "Couch"}]},
                    },
                )
                assert await d.wait_for(lambda: d.counts()["late"] == 1, 3)
            return d

    d = run(main())
    last = [e for e in d.transcript.entries if e.speaker == "robot"][-1]
    assert last.text == "I see a couch." and last.extra.get("late") is True
    assert d.counts()["timeouts"] == 1 and d.counts()["replies"] == 0


def test_render_reply_prefers_content_and_falls_back_to_text() -> None:
    say = {"schema": "loci.say/1", "text": "agent words", "content": {"area": {"class": "corridor"}}}
    assert render_reply(say, "ask_place") == "I am in the corridor."
    assert render_reply(say, None) == "agent words"
    assert render_reply({"text": "agent words", "content": {}}, "ask_place") == "agent words"
    assert render_reply({"text": "No.", "status": "error", "content": {"area": {}}}, "ask_place") == "No."


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="loci")
    dialogue_command.register(parser.add_subparsers(dest="command", required=True))
    return parser


def test_cli_script_with_transcript(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``loci dialogue --script`` as the demo runs it, against an agent peer listening on loopback."""
    agent_session = open_session(BusConfig())
    try:
        peer = AgentPeer(agent_session)
        endpoint = listening_endpoints(agent_session)[0]
        script = tmp_path / "tour.txt"
        script.write_text("Where am I?\n\nGo to a room with a couch\n@wait-task 5\nsing\n", encoding="utf-8")
        transcript = tmp_path / "tour.txt.log"
        args = _parser().parse_args(
            [
                "dialogue",
                "--robot",
                ROBOT,
                "--connect",
                endpoint,
                "--script",
                str(script),
                "--transcript",
                str(transcript),
                "--no-speech",
                "--reply-timeout",
                "3",
            ]
        )
        status = args.handler(args)
    finally:
        close_session(agent_session)
    out = capsys.readouterr().out
    assert status == 0, out
    assert peer.kinds() == ["ask_place", "go_to"]
    assert peer.intents[1]["args"]["target"]["with"] == ["couch"]
    assert "robot: I am going to a room with a couch, 12 metres away." in out
    assert "robot: I have reached a room with a couch." in out
    assert 'robot: Sorry, I did not understand "sing".' in out
    text = transcript.read_text(encoding="utf-8").splitlines()
    assert any(line.endswith("tutor: Where am I?") for line in text)
    assert any(line.endswith("robot: I am in the living room.") for line in text)
    assert not text[0].startswith("{")  # plain text, not JSON lines


def test_cli_rejects_bad_options() -> None:
    parser = _parser()
    for argv in (
        ["dialogue", "--console", "--heard-only"],
        ["dialogue", "--reply-timeout", "0"],
        ["dialogue", "--pause", "x"],
    ):
        with pytest.raises(SystemExit):
            parser.parse_args(argv)
    args = parser.parse_args(["dialogue", "--heard-only", "--connect", "tcp/127.0.0.1:9"])
    config = dialogue_command.config_from_args(args)
    assert (config.console, config.heard, config.bus.connect) == (False, True, ("tcp/127.0.0.1:9",))


def test_json_transcript_lines_are_json(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "t.jsonl"
    with Transcript(path) as t:
        t.add("tutor", "utterance", "Where are you?", source="console")
        t.add("robot", "say", "I am in a room.", in_reply_to="x-1")
    docs = [json.loads(line) for line in path.read_text().splitlines()]
    assert [(d["speaker"], d["text"]) for d in docs] == [
        ("tutor", "Where are you?"),
        ("robot", "I am in a room."),
    ]
    assert docs[1]["in_reply_to"] == "x-1"


def test_console_lines_until_end_of_input(tmp_path: Path) -> None:
    """run_dialogue reading a console (stdin ends after two lines) and exiting after the last reply."""
    from agent.dialogue.process import DialogueConfig, run_dialogue

    agent_session = open_session(BusConfig())
    out = io.StringIO()
    try:
        peer = AgentPeer(agent_session)
        config = DialogueConfig(
            robot=ROBOT,
            bus=BusConfig(connect=tuple(listening_endpoints(agent_session))),
            heard=False,
            transcript=tmp_path / "console.jsonl",
            speech=False,
            reply_timeout=3.0,
        )
        status = run(run_dialogue(config, stdin=io.StringIO("Where are you?\nLook around\n"), out=out))
    finally:
        close_session(agent_session)
    assert status == 0
    assert peer.kinds() == ["ask_place", "look_around"]
    assert out.getvalue().splitlines() == ["robot: I am in the living room.", "robot: I see a television."]
    kinds = [e["kind"] for e in read_transcript(tmp_path / "console.jsonl")]
    # the console does not wait for replies: a person may type on while the robot answers
    assert sorted(kinds) == ["intent", "intent", "say", "say", "utterance", "utterance"]
    assert kinds[:2] == ["utterance", "intent"] and kinds[-1] == "say"
