"""Zenoh key expressions of the robot's streams, and how each stream is delivered.

Every key is ``loci/<robot>/<stream>``; ``<robot>`` defaults to the host name. The table
:data:`STREAMS` is the one list of streams: its key suffix, payload schema, direction and
delivery policy. ``docs/bus.md`` shows the same table for people.

Robot names are one key chunk: letters, digits, ``_``, ``-`` and ``.``, starting with a
letter or digit (no ``/``, no wildcards ``*``, ``$``, ``?``, ``#``, no spaces).
"""

from __future__ import annotations

import enum
import re
import socket
from dataclasses import dataclass

#: The first chunk of every key.
PREFIX = "loci"

_ROBOT = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,62}")
_CHUNK = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


class Policy(enum.Enum):
    """What a full receive queue does with a new sample.

    ``DROP_OLDEST``: the oldest queued sample is dropped and counted (sensor data: only the
    newest matters). ``WAIT``: Zenoh's callback thread waits for room, for a bounded time,
    then drops the new sample and counts it (commands: none should be lost while the agent
    keeps up, but a stalled agent must not stall the Zenoh session). Publishers of ``WAIT``
    streams use Zenoh's blocking congestion control, those of ``DROP_OLDEST`` streams drop.
    """

    DROP_OLDEST = "drop-oldest"
    WAIT = "wait"


@dataclass(frozen=True)
class StreamSpec:
    """One stream of the bus.

    Attributes:
        name: the key suffix after ``loci/<robot>/`` (e.g. ``"scan"``, ``"dialogue/intent"``).
        schema: the payload schema: a Foxglove protobuf name (``"foxglove.LaserScan"``) or a
            versioned JSON schema id (``"loci.place/1"``).
        direction: who publishes to whom, for the docs.
        policy: what a full receive queue does (see :class:`Policy`).
        description: one line for the docs.
    """

    name: str
    schema: str
    direction: str
    policy: Policy
    description: str


#: Every stream, by name. Queryables are in :data:`STATE_KEYS` (``state/...``) and
#: :data:`REQUEST_KEYS`.
STREAMS: dict[str, StreamSpec] = {
    s.name: s
    for s in (
        StreamSpec(
            "scan", "foxglove.LaserScan", "driver → agent", Policy.DROP_OLDEST, "laser scans as measured"
        ),
        StreamSpec(
            "scan/full",
            "foxglove.LaserScan",
            "agent → all",
            Policy.DROP_OLDEST,
            "the 360° scan the classifier saw (rear beams simulated for a front laser)",
        ),
        StreamSpec("odom", "foxglove.PoseInFrame", "base → agent", Policy.DROP_OLDEST, "odometry pose"),
        StreamSpec(
            "tf",
            "foxglove.FrameTransform",
            "agent → all",
            Policy.DROP_OLDEST,
            "odom → laser transform, so Foxglove draws scans in the odometry frame",
        ),
        StreamSpec("camera", "foxglove.CompressedImage", "driver → agent", Policy.DROP_OLDEST, "JPEG frames"),
        StreamSpec(
            "place",
            "loci.place/1",
            "agent → all",
            Policy.DROP_OLDEST,
            "current class, probabilities, node, coverage",
        ),
        StreamSpec("graph", "loci.graph/1", "agent → all", Policy.DROP_OLDEST, "the navigation graph"),
        StreamSpec(
            "graph/scene",
            "foxglove.SceneUpdate",
            "agent → all",
            Policy.DROP_OLDEST,
            "the graph for Foxglove's 3D panel",
        ),
        StreamSpec("areas", "loci.areas/1", "agent → all", Policy.DROP_OLDEST, "topological areas"),
        StreamSpec(
            "areas/scene",
            "foxglove.SceneUpdate",
            "agent → all",
            Policy.DROP_OLDEST,
            "area labels for Foxglove",
        ),
        StreamSpec(
            "diagnostics", "loci.diagnostics/1", "agent → all", Policy.DROP_OLDEST, "per-stream counters"
        ),
        StreamSpec("dialogue/heard", "loci.utterance/1", "speech → dialogue", Policy.WAIT, "utterance text"),
        StreamSpec(
            "dialogue/intent", "loci.intent/1", "dialogue → agent", Policy.WAIT, "a structured request"
        ),
        StreamSpec(
            "dialogue/say", "loci.say/1", "agent → dialogue", Policy.WAIT, "what the robot wants said"
        ),
        StreamSpec("dialogue/ask", "loci.ask/1", "agent → dialogue", Policy.WAIT, "a question to a person"),
        StreamSpec("base/cmd", "loci.twist/1", "agent → base", Policy.WAIT, "velocity command"),
        StreamSpec(
            "base/goal", "loci.base_goal/1", "agent → base", Policy.WAIT, "a goal pose or a path of waypoints"
        ),
        StreamSpec(
            "base/status",
            "loci.base_status/1",
            "base → agent",
            Policy.WAIT,
            "what the base does: goal active, reached, failed, collided",
        ),
        StreamSpec(
            "people",
            "loci.people/1",
            "agent → all",
            Policy.DROP_OLDEST,
            "people in every laser scan: legs, persons, tracks (odometry frame)",
        ),
        StreamSpec(
            "people/scene",
            "foxglove.SceneUpdate",
            "agent → all",
            Policy.DROP_OLDEST,
            "the people's tracks and legs for Foxglove's 3D panel",
        ),
        StreamSpec(
            "objects",
            "loci.objects/1",
            "agent → all",
            Policy.DROP_OLDEST,
            "objects the camera recognised, with the node and area they were seen from",
        ),
        StreamSpec(
            "map/edit",
            "loci.map_edit/1",
            "agent → all",
            Policy.WAIT,
            "a change of the map made by the dialogue (a doorway removed); replay applies it again",
        ),
        StreamSpec(
            "sim/truth",
            "loci.truth/1",
            "simulator → evaluation",
            Policy.DROP_OLDEST,
            "the simulated robot's true pose and place class (for evaluation only)",
        ),
        StreamSpec(
            "tf/map",
            "foxglove.FrameTransform",
            "agent → all",
            Policy.DROP_OLDEST,
            "map → odom transform: the localization's correction of the odometry",
        ),
        StreamSpec(
            "localization/pose",
            "loci.pose/1",
            "agent → all",
            Policy.DROP_OLDEST,
            "the robot's pose in the map with its covariance",
        ),
        StreamSpec(
            "localization/status",
            "loci.localization/1",
            "agent → all",
            Policy.WAIT,
            "how sure the tracked pose is: its state and σ, when they change or a correction happens",
        ),
        StreamSpec(
            "localization/scene",
            "foxglove.SceneUpdate",
            "agent → all",
            Policy.DROP_OLDEST,
            "the particles, the estimate and its covariance ellipse for Foxglove's 3D panel",
        ),
        StreamSpec(
            "pose/truth",
            "foxglove.PoseInFrame",
            "log import → evaluation",
            Policy.DROP_OLDEST,
            "a log's reference pose of the robot (TRUEPOS, SLAM-corrected poses), frame map (for evaluation only)",
        ),
    )
}

#: Queryables under ``loci/<robot>/state/``: name → the schema of the reply.
STATE_KEYS: dict[str, str] = {
    "graph": "loci.graph/1",
    "areas": "loci.areas/1",
    "place": "loci.place/1",
    "concepts": "loci.concepts/1",
}

#: Queryables that do something on request, ``loci/<robot>/<name>``: name → the schemas of the
#: request (the query's payload) and of the reply (an error reply is ``loci.error/1``).
REQUEST_KEYS: dict[str, tuple[str, str]] = {
    "map/save": ("loci.map_save/1", "loci.map_saved/1"),
}


def default_robot_name() -> str:
    """The host name made into a valid robot name (invalid characters become ``-``)."""
    host = socket.gethostname().split(".")[0] or "robot"
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", host)
    if not name[0].isalnum():
        name = "r" + name
    return name[:63]


def robot_name(name: str | None = None) -> str:
    """A validated robot name; ``None`` or ``""`` means :func:`default_robot_name`.

    Raises:
        ValueError: the name cannot be a single key chunk.
    """
    if not name:
        return default_robot_name()
    if not _ROBOT.fullmatch(name):
        raise ValueError(
            f"robot name {name!r} cannot be part of a Zenoh key: use 1-63 letters, digits, '_', '-' "
            "or '.', starting with a letter or digit (e.g. 'rosie-2')"
        )
    return name


def stream_key(robot: str, stream: str) -> str:
    """``loci/<robot>/<stream>`` after validating both parts.

    ``stream`` may have several chunks (``"dialogue/intent"``) but no wildcards.
    """
    robot = robot_name(robot)
    chunks = stream.split("/")
    if not stream or not all(_CHUNK.fullmatch(c) for c in chunks):
        raise ValueError(
            f"stream name {stream!r} must be '/'-separated chunks of letters, digits, '_', '-', '.' "
            "(no wildcards, no empty chunks), e.g. 'scan' or 'dialogue/intent'"
        )
    return f"{PREFIX}/{robot}/{stream}"


def state_key(robot: str, name: str) -> str:
    """The key of a state queryable: ``loci/<robot>/state/<name>``."""
    return stream_key(robot, f"state/{name}")


#: The processes of a robot that say they are ready (liveliness tokens ``loci/<robot>/ready/<role>``).
READY_ROLES = ("agent", "sim", "dialogue")


def ready_key(robot: str, role: str) -> str:
    """The liveliness token a process of ``robot`` declares when it is ready to work:
    ``loci/<robot>/ready/<role>`` (``role`` one of :data:`READY_ROLES`, or ``*``)."""
    if role != "*" and role not in READY_ROLES:
        raise ValueError(f"role must be one of {READY_ROLES} (or '*'), got {role!r}")
    return f"{PREFIX}/{robot_name(robot)}/ready/{role}"


def robot_wildcard(robot: str) -> str:
    """``loci/<robot>/**``: every stream and queryable of one robot (what a recorder subscribes)."""
    return f"{PREFIX}/{robot_name(robot)}/**"


@dataclass(frozen=True)
class RobotKeys:
    """The keys of one robot: ``RobotKeys("rosie").scan == "loci/rosie/scan"``."""

    robot: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "robot", robot_name(self.robot))

    def stream(self, name: str) -> str:
        return stream_key(self.robot, name)

    def state(self, name: str) -> str:
        return state_key(self.robot, name)

    def ready(self, role: str) -> str:
        return ready_key(self.robot, role)

    @property
    def all(self) -> str:
        return robot_wildcard(self.robot)

    @property
    def scan(self) -> str:
        return self.stream("scan")

    @property
    def odom(self) -> str:
        return self.stream("odom")

    @property
    def camera(self) -> str:
        return self.stream("camera")

    @property
    def place(self) -> str:
        return self.stream("place")

    @property
    def graph(self) -> str:
        return self.stream("graph")

    @property
    def areas(self) -> str:
        return self.stream("areas")

    @property
    def diagnostics(self) -> str:
        return self.stream("diagnostics")


def spec_for_key(key: str) -> StreamSpec | None:
    """The :class:`StreamSpec` of a concrete key ``loci/<robot>/<stream>``, or None if unknown."""
    parts = key.split("/", 2)
    if len(parts) != 3 or parts[0] != PREFIX:
        return None
    return STREAMS.get(parts[2])
