"""Argument types, option groups and output helpers shared by the ``loci`` commands.

The types raise :class:`argparse.ArgumentTypeError`, so a bad value is a usage error that
names the option (exit status 2), never a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
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


def emit_json(obj: dict[str, Any]) -> None:
    """``--json`` output: one indented JSON object on stdout (NaN refused: it is not JSON)."""
    json.dump(obj, sys.stdout, indent=2, allow_nan=False)
    sys.stdout.write("\n")


def pct(v: float) -> str:
    """A fraction as a fixed-width percentage: ``0.9312`` → ``" 93.12 %"``."""
    return f"{100 * v:6.2f} %"
