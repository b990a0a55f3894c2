"""``loci dialogue``: the reference speech/dialogue process, talking to the agent over Zenoh.

It reads a tutor's utterances from the console (one per line), from a script file, or as text
from any speech recogniser publishing ``loci.utterance/1`` on ``loci/ROBOT/dialogue/heard``;
understands the guided-tour language; sends ``loci.intent/1`` to the agent; and prints and
speaks (espeak-ng) the robot's replies and questions. docs/dialogue.md has the grammar.
"""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path
from typing import Any

from agent.commands.options import add_bus_options, positive_seconds, seconds


def register(subparsers: Any) -> None:
    from agent.dialogue.process import DEFAULT_REPLY_TIMEOUT

    p = subparsers.add_parser(
        "dialogue",
        help="talk to the robot: console or speech recogniser text in, spoken answers out",
        description=(
            "The dialogue process: understands a tutor's guided-tour language ('You are in the corridor', "
            "'This is the kitchen', 'Where is the television?', 'Go to a room with a couch', 'Follow me', "
            "'Stop'), sends intents to the agent over Zenoh and speaks its replies and questions "
            "(espeak-ng when installed). Utterances come from the console (stdin lines), a --script, "
            "and speech recognisers publishing on loci/ROBOT/dialogue/heard."
        ),
        epilog=(
            "Examples: loci dialogue --robot rosie;  "
            "loci dialogue --script tour.txt --transcript tour.jsonl --no-speech;  "
            "loci dialogue --heard-only --voice en-us"
        ),
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help=(
            "the robot's TOML (as for loci run): its [robot] name and its [bus] (mode, the router "
            "or the agent to connect to, config_file with this process's Zenoh user); the options "
            "below override it"
        ),
    )
    add_bus_options(p)
    source = p.add_mutually_exclusive_group()
    source.add_argument(
        "--console", action="store_true", help="only the console: ignore loci/ROBOT/dialogue/heard"
    )
    source.add_argument(
        "--heard-only",
        action="store_true",
        help="only utterances published on loci/ROBOT/dialogue/heard (no console); runs until Ctrl-C",
    )
    p.add_argument(
        "--script",
        type=Path,
        metavar="FILE",
        help="say the tutor lines of FILE (one per line; '#' comments, 'NAME: text', @sleep S, "
        "@wait-task [S], @wait-ask [S]), then exit; exit status 1 if a line got no reply",
    )
    p.add_argument(
        "--no-wait",
        action="store_true",
        help="in a script, do not wait for each line's reply before the next",
    )
    p.add_argument(
        "--pause", type=seconds, default=0.0, metavar="S", help="seconds between script lines (default 0)"
    )
    p.add_argument(
        "--transcript",
        type=Path,
        metavar="FILE",
        help="append every line with its time and speaker to FILE (*.jsonl: JSON lines, else plain text)",
    )
    p.add_argument("--no-speech", action="store_true", help="print the robot's lines, do not speak them")
    p.add_argument("--voice", metavar="VOICE", help="the espeak-ng voice (e.g. en, en-us, en+f3)")
    p.add_argument(
        "--reply-timeout",
        type=positive_seconds,
        default=DEFAULT_REPLY_TIMEOUT,
        metavar="S",
        help=f"report an intent unanswered after S seconds (default {DEFAULT_REPLY_TIMEOUT:g})",
    )
    p.add_argument(
        "--speaker", default="tutor", help="the name of who types or whose script it is (default tutor)"
    )
    p.set_defaults(handler=_dialogue)


def config_from_args(args: argparse.Namespace) -> Any:
    """The :class:`~agent.dialogue.process.DialogueConfig` of parsed arguments."""
    from agent.bus.session import DEFAULT_AGENT_ENDPOINT, BusConfig
    from agent.dialogue.process import DialogueConfig

    robot = args.robot
    if getattr(args, "config", None) is not None:
        bus, robot = _from_robot_config(args)
    else:
        bus = BusConfig(
            listen=tuple(args.listen or ("tcp/127.0.0.1:0",)),
            connect=tuple(args.connect or (DEFAULT_AGENT_ENDPOINT,)),
            config_file=args.zenoh_config,
        )
    return DialogueConfig(
        robot=robot,
        bus=bus,
        console=not args.heard_only,
        heard=not args.console,
        script=args.script,
        wait=not args.no_wait,
        pause=args.pause,
        transcript=args.transcript,
        speech=not args.no_speech,
        voice=args.voice,
        reply_timeout=args.reply_timeout,
        speaker=args.speaker,
    )


def _from_robot_config(args: argparse.Namespace) -> tuple[Any, str | None]:
    """The bus and robot name of ``--config``: a client of the same router, or a peer of the agent.

    In peer mode the agent listens on the file's ``listen`` endpoints; this process connects
    to them (and listens on a free port of its own), so both can run from one file.
    """
    from agent.bus.session import BusConfig
    from agent.config import load_config

    config = load_config(args.config)
    agent_bus = config.bus
    if agent_bus.mode == "client":
        bus = BusConfig(
            mode="client",
            listen=(),
            connect=tuple(args.connect or agent_bus.connect),
            config_file=getattr(args, "zenoh_config", None) or agent_bus.config_file,
        )
    else:
        bus = BusConfig(
            listen=tuple(args.listen or ("tcp/127.0.0.1:0",)),
            connect=tuple(args.connect or (*agent_bus.connect, *agent_bus.listen)),
            config_file=getattr(args, "zenoh_config", None) or agent_bus.config_file,
        )
    return bus, args.robot or config.robot.name or None


def _dialogue(args: argparse.Namespace) -> int:
    from agent.dialogue.process import run_dialogue

    return asyncio.run(run_dialogue(config_from_args(args)))
