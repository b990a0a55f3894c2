"""The simulated tutor's two bus messages (the demo's own keys).

``loci/<robot>/sim/tutor`` (``loci.tutor_cmd/1``, JSON, demo → simulator): what the tutor
does next, one of

* ``{"walk": "into_room"}``: walk a leg of the tour (:data:`sim.tour.LEG_NAMES`);
* ``{"walk": [[x, y], ...]}``: walk these map-frame waypoints (metres);
* ``{"stop": true}``: stand where it is.

``loci/<robot>/sim/tutor/state`` (``loci.tutor_state/1``, JSON, simulator → all, a few
times per second): ``{"x", "y", "heading", "walking", "waiting", "remaining", "walks"}``,
the tutor's body in the map frame (metres, radians), whether it has a walk to finish,
whether it waits for the robot, metres left, and how many walks it has finished.

Both are JSON with the Zenoh encoding ``application/json`` (a recorder keeps them without a
schema); their one definition is in :mod:`agent.bus.schemas` (``TUTOR_CMD``,
``TUTOR_STATE``). Validation errors are :class:`ValueError` s that say what is wrong.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

from agent.bus.keys import stream_key
from agent.bus.schemas import SCHEMAS

__all__ = [
    "ENCODING",
    "TUTOR_CMD",
    "TUTOR_STATE",
    "decode",
    "encode",
    "state_message",
    "tutor_cmd_key",
    "tutor_state_key",
    "validate_cmd",
    "walk_cmd",
]

TUTOR_CMD = "loci.tutor_cmd/1"
TUTOR_STATE = "loci.tutor_state/1"
ENCODING = "application/json"


def tutor_cmd_key(robot: str) -> str:
    """``loci/<robot>/sim/tutor``."""
    return stream_key(robot, "sim/tutor")


def tutor_state_key(robot: str) -> str:
    """``loci/<robot>/sim/tutor/state``."""
    return stream_key(robot, "sim/tutor/state")


def walk_cmd(walk: str | Sequence[Sequence[float]]) -> dict[str, Any]:
    """A command to walk a leg by name, or waypoints ``[(x, y), ...]`` (metres, map frame)."""
    if isinstance(walk, str):
        msg: dict[str, Any] = {"schema": TUTOR_CMD, "walk": walk}
    else:
        msg = {"schema": TUTOR_CMD, "walk": [[float(p[0]), float(p[1])] for p in walk]}
    return validate_cmd(msg)


def validate_cmd(msg: Mapping[str, Any]) -> dict[str, Any]:
    """``msg`` checked as a ``loci.tutor_cmd/1`` (:data:`agent.bus.schemas.TUTOR_CMD`, its one
    definition; ``schema`` may be left out), as a new dict with waypoints as floats.

    Raises:
        ValueError: not a tutor command; the message says which part is wrong.
    """
    if not isinstance(msg, Mapping):
        raise ValueError("a tutor command is a JSON object")
    doc = {"schema": TUTOR_CMD, **msg}
    SCHEMAS.validate(doc, TUTOR_CMD)
    if doc.get("stop") is True:
        return {"schema": TUTOR_CMD, "stop": True}
    walk = doc["walk"]
    if isinstance(walk, str):
        return {"schema": TUTOR_CMD, "walk": walk}
    return {"schema": TUTOR_CMD, "walk": [[float(x), float(y)] for x, y in walk]}


def state_message(
    xy: Sequence[float], heading: float, *, walking: bool, waiting: bool, remaining: float, walks: int
) -> dict[str, Any]:
    """A ``loci.tutor_state/1`` message."""
    return {
        "schema": TUTOR_STATE,
        "x": round(float(xy[0]), 4),
        "y": round(float(xy[1]), 4),
        "heading": round(float(heading), 4),
        "walking": bool(walking),
        "waiting": bool(waiting),
        "remaining": round(float(remaining), 3),
        "walks": int(walks),
    }


def encode(msg: Mapping[str, Any]) -> bytes:
    """JSON bytes of a message."""
    return json.dumps(msg, separators=(",", ":")).encode("utf-8")


def decode(data: bytes) -> dict[str, Any]:
    """A JSON object from bytes.

    Raises:
        ValueError: not UTF-8 JSON, or not an object.
    """
    try:
        msg = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not a JSON message: {exc}") from None
    if not isinstance(msg, dict):
        raise ValueError("a tutor message is a JSON object")
    return msg
