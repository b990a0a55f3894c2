"""Argument types, option groups and output helpers shared by the ``loci`` commands and the
``python -m tools.X`` programs.

The types raise :class:`argparse.ArgumentTypeError`, so a bad value is a usage error that
names the option (exit status 2), never a traceback.

JSON output has one meaning everywhere (docs/tools.md, "JSON output"; a test walks every
parser and checks it):

- ``--json`` is a flag: print exactly one JSON object on stdout *instead of* the text, and
  nothing else on stdout (progress, logs and warnings go to stderr), so
  ``loci ... --json | jq`` and ``json.loads(stdout)`` work (:func:`add_json_option`,
  :func:`emit_json`);
- ``--json-file FILE`` writes that same object to FILE (atomically) and leaves stdout as it is,
  for a program whose text report is worth keeping beside its numbers (the benchmarks under
  ``make bench``; :func:`add_json_file_option`, :func:`write_json_file`);
- ``--json-lines`` is for a stream of records: one compact JSON object per line on stdout, as
  they happen (``loci sick scan``).

No other spelling (``--json FILE``, ``--json [FILE]``, JSON lines under ``--json``) is used.
The helpers here refuse non-finite numbers: NaN and Infinity are not JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any


def number(*, minimum: float = 0.0, inclusive: bool = False, what: str = "number") -> Callable[[str], float]:
    """A float option above ``minimum`` (or at least it, with ``inclusive``), finite."""
    bound = f">= {minimum:g}" if inclusive else ("positive" if minimum == 0 else f"> {minimum:g}")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value) and (value >= minimum if inclusive else value > minimum)
        if not ok:
            raise argparse.ArgumentTypeError(f"expected a {bound} {what}, got {text!r}")
        return value

    return parse


def integer(*, minimum: int = 1, why: str = "") -> Callable[[str], int]:
    """An int option of at least ``minimum`` (``why`` says the reason for a minimum above 1)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}") from None
        if value < minimum:
            reason = f" ({why})" if why else ""
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}{reason}, got {value}")
        return value

    return parse


def fraction(text: str) -> float:
    """A float strictly between 0 and 1."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1), got {text!r}") from None
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1), got {value:g}")
    return value


#: seconds > 0 (durations, timeouts)
positive_seconds = number(what="number of seconds")
#: seconds >= 0 (pauses)
seconds = number(inclusive=True, what="number of seconds")
positive_float = number()
positive_int = integer()


def add_bus_options(parser: argparse.ArgumentParser, *, mode: bool = False) -> None:
    """``--robot``, ``--connect``, ``--listen`` (and ``--mode``): how a process joins the robot's bus."""
    from agent.bus.session import DEFAULT_AGENT_ENDPOINT

    parser.add_argument(
        "--robot", help="the robot's name, the second chunk of its keys (default: this host's name)"
    )
    parser.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        help=f"a Zenoh endpoint to connect to, repeatable (default: {DEFAULT_AGENT_ENDPOINT}, the agent's)",
    )
    parser.add_argument(
        "--listen",
        metavar="ENDPOINT",
        action="append",
        help="an endpoint to accept connections on, repeatable (default: tcp/127.0.0.1:0, a free port)",
    )
    if mode:
        parser.add_argument(
            "--mode", choices=("peer", "client"), default="peer", help="peer (default) or client of a router"
        )
    parser.add_argument(
        "--zenoh-config",
        metavar="FILE.json5",
        default=os.environ.get("LOCI_BUS_CONFIG_FILE"),
        help=(
            "a Zenoh JSON5 configuration to start from: the user and password the router expects, "
            "TLS (e.g. /etc/loci/zenoh/tools.json5; default: $LOCI_BUS_CONFIG_FILE); the options "
            "above are set over it"
        ),
    )


#: the help of ``--json``, the same in every program
JSON_HELP = "print one JSON object on stdout instead of the text"


def add_json_option(parser: argparse._ActionsContainer, help: str = JSON_HELP) -> None:
    """``--json``: a flag, one JSON object on stdout instead of the text."""
    parser.add_argument("--json", action="store_true", help=help)


def add_json_file_option(parser: argparse._ActionsContainer, help: str | None = None) -> None:
    """``--json-file FILE``: also write the JSON object to FILE (stdout unchanged)."""
    parser.add_argument(
        "--json-file",
        type=Path,
        metavar="FILE",
        help=help or "also write the result as one JSON object to FILE (the text still goes to stdout)",
    )


def json_text(obj: dict[str, Any], *, indent: int | None = 2) -> str:
    """``obj`` as JSON text ending in a newline; NaN and Infinity refused (they are not JSON)."""
    return json.dumps(obj, indent=indent, allow_nan=False) + "\n"


def emit_json(obj: dict[str, Any]) -> None:
    """``--json`` output: one indented JSON object on stdout (NaN refused: it is not JSON)."""
    sys.stdout.write(json_text(obj))
    sys.stdout.flush()


def emit_json_line(obj: dict[str, Any]) -> None:
    """``--json-lines`` output: one record as one compact line on stdout, flushed at once."""
    sys.stdout.write(json_text(obj, indent=None))
    sys.stdout.flush()


def write_json_file(path: Path, obj: dict[str, Any]) -> None:
    """``--json-file`` output: ``obj`` written atomically to ``path`` (its folder made)."""
    from knowledge.fileio import atomic_write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json_text(obj))


def emit_result(
    args: argparse.Namespace, result: dict[str, Any], text: Callable[[dict[str, Any]], str]
) -> None:
    """The end of a program with ``--json`` and ``--json-file``: ``result`` to the file if one
    was given, then on stdout either ``result`` as JSON (``--json``) or ``text(result)``."""
    path = getattr(args, "json_file", None)
    if path is not None:
        write_json_file(path, result)
    if args.json:
        emit_json(result)
    else:
        print(text(result), flush=True)


def pct(v: float) -> str:
    """A fraction as a fixed-width percentage: ``0.9312`` → ``" 93.12 %"``."""
    return f"{100 * v:6.2f} %"
