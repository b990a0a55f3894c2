"""``loci``: the genius-loci command line.

Each command group lives in its own module under :mod:`agent.commands` and registers its
sub-commands; heavy imports happen inside the handlers so ``loci --help`` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
import traceback
from collections.abc import Sequence

from knowledge.errors import LociError

#: Command modules, in the order ``loci --help`` lists them.
COMMAND_MODULES: list[str] = [
    "agent.commands.demo",
    "agent.commands.places",
    "agent.commands.people",
    "agent.commands.sick",
    "agent.commands.sim",
    "agent.commands.record",
    "agent.commands.import_",
    "agent.commands.run",
    "agent.commands.replay",
    "agent.commands.evaluate",
    "agent.commands.localize",
    "agent.commands.map",
    "agent.commands.dialogue",
    "agent.commands.objects",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="loci",
        description=(
            "genius-loci: a robot agent that knows what the places around it are. "
            "It classifies places from 2D laser scans (corridor, room, doorway, hallway), "
            "builds layered maps of them and talks about them."
        ),
        epilog="Run 'loci COMMAND --help' for the options of a command.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    _log_options_everywhere(sub)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("genius-loci")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "(not installed)"


def _log_options_everywhere(sub: argparse._SubParsersAction) -> None:
    """``-v`` and ``-q`` are also accepted after a command (``loci replay run.mcap -v``), at
    every level of sub-commands, as if given before the command."""
    for parser in sub.choices.values():
        known = {opt for action in parser._actions for opt in action.option_strings}
        if "-v" not in known:
            parser.add_argument(
                "-v", "--verbose", action="count", default=argparse.SUPPRESS, help=argparse.SUPPRESS
            )
        if "-q" not in known and "--quiet" not in known:
            parser.add_argument(
                "-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
            )
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                _log_options_everywhere(action)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING if args.quiet else (logging.INFO if args.verbose == 0 else logging.DEBUG)
    logging.basicConfig(
        level=level, format="%(asctime)s %(levelname)-7s %(name)s: %(message)s", datefmt="%H:%M:%S"
    )
    try:
        result = args.handler(args)
    except (LociError, ValueError) as exc:
        # LociErrors and bad values say what is wrong and what to do: no traceback (but -v shows it)
        if args.verbose:
            traceback.print_exc()
        print(f"loci: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("loci: interrupted", file=sys.stderr)
        return 130
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
