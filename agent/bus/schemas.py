"""The bus's JSON messages, each defined once (:mod:`knowledge.schema` is the vocabulary).

:data:`SCHEMAS` holds every message of the bus (``loci.place/1``, ``loci.graph/1``, ...);
docs/bus.md shows the same table, made from it. Other modules may
:meth:`~knowledge.schema.SchemaRegistry.register` more.
"""

from __future__ import annotations

from typing import Any

from knowledge.errors import ProtocolError
from knowledge.schema import (
    MAX_JSON_BYTES,
    MAX_JSON_DEPTH,
    SMALL_MESSAGE_BYTES,
    MessageSchema,
    SchemaRegistry,
    Spec,
    array,
    boolean,
    check_value,
    integer,
    json_depth,
    mapping,
    number,
    obj,
    string,
)

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "SCHEMAS",
    "SMALL_MESSAGE_BYTES",
    "MessageSchema",
    "SchemaRegistry",
    "Spec",
    "json_depth",
]

# ---- the project's messages -------------------------------------------------------------

_STAMP = number(minimum=0, description="seconds since the Unix epoch")
_PROBABILITY = number(minimum=0, maximum=1)
_CLASS = string(max_length=64, description="place class: room, corridor, doorway, hallway, ...")
_NODE_ID = integer(minimum=0)


def _graph_checks(message: dict[str, Any]) -> str | None:
    ids = [n["id"] for n in message["nodes"]]
    known = set(ids)
    if len(known) != len(ids):
        return "nodes: node ids must be unique"
    for i, (a, b) in enumerate(message["edges"]):
        if a not in known or b not in known:
            return f"edges[{i}]: [{a}, {b}] names a node that is not in 'nodes'"
    return None


def _area_checks(message: dict[str, Any]) -> str | None:
    ids = [a["id"] for a in message["areas"]]
    if len(set(ids)) != len(ids):
        return "areas: area ids must be unique"
    return None


PLACE = MessageSchema(
    "loci.place",
    1,
    obj(
        {
            "stamp": _STAMP,
            "label": _CLASS,
            "probabilities": mapping(_PROBABILITY, description="class → probability"),
        },
        {
            "node": integer(minimum=0, nullable=True, description="the navigation node the robot is at"),
            "coverage": number(
                minimum=0,
                maximum=1,
                description="share of the 360° scan's beams measured or hit in the local map "
                "(the rest interpolated); below the graph's min_coverage the label does not vote",
            ),
            "pose": obj(
                {
                    "x": number(description="metres"),
                    "y": number(description="metres"),
                    "theta": number(description="heading, radians, counter-clockwise"),
                },
                description="the laser's pose in the odometry frame at the scan's stamp",
            ),
            "raw_probabilities": mapping(
                _PROBABILITY, description="class → probability: the classifier's histogram of this scan"
            ),
            "filtered_probabilities": mapping(
                _PROBABILITY,
                nullable=True,
                description="class → probability: the trajectory HMM's belief after this scan (null: no HMM)",
            ),
        },
    ),
    description="the place the robot is in now: the class that votes for navigation nodes and its "
    "probabilities (the HMM's belief, or the classifier's histogram), and both histograms",
)

GRAPH = MessageSchema(
    "loci.graph",
    1,
    obj(
        {
            "stamp": _STAMP,
            "nodes": array(
                obj(
                    {
                        "id": _NODE_ID,
                        "x": number(description="metres, odometry frame"),
                        "y": number(description="metres, odometry frame"),
                        "kind": string(choices=("place", "doorway")),
                        "label": string(max_length=64, nullable=True, description="majority class"),
                    },
                    {
                        "width": number(minimum=0, nullable=True, description="doorway width, metres"),
                        "orientation": number(nullable=True, description="doorway normal, radians"),
                    },
                )
            ),
            "edges": array(array(_NODE_ID, min_items=2, max_items=2)),
        },
        {"frame_id": string(max_length=64)},
    ),
    checks=(_graph_checks,),
    description="the navigation graph: nodes dropped along the robot's path, edges between them",
)

AREAS = MessageSchema(
    "loci.areas",
    1,
    obj(
        {
            "stamp": _STAMP,
            "areas": array(
                obj(
                    {
                        "id": integer(minimum=0),
                        "label": string(max_length=64, nullable=True),
                        "nodes": array(_NODE_ID, min_items=1),
                    }
                )
            ),
        }
    ),
    checks=(_area_checks,),
    description="topological areas: connected place nodes, split at doorways, with their class",
)

_COUNTERS = obj(
    {
        "received": integer(minimum=0),
        "delivered": integer(minimum=0),
        "dropped": integer(minimum=0),
        "invalid": integer(minimum=0),
    },
    {"published": integer(minimum=0), "queued": integer(minimum=0)},
)

DIAGNOSTICS = MessageSchema(
    "loci.diagnostics",
    1,
    obj(
        {"stamp": _STAMP, "robot": string(max_length=63), "streams": mapping(_COUNTERS)},
        {"uptime": number(minimum=0, description="seconds"), "extra": mapping(Spec("any"))},
    ),
    description="per-stream counters of the bus: received, delivered, dropped, invalid",
)

ERROR = MessageSchema(
    "loci.error",
    1,
    obj({"reason": string()}, {"key": string(), "stamp": _STAMP}),
    description="an error answer to a query or request",
)

# ---- the dialogue (agent/conversation/agent.py, agent/dialogue/, docs/dialogue.md) ----------------

#: What a ``loci.intent/1`` can ask of the agent, and the ``args`` each kind takes.
INTENT_KINDS = (
    "assert_type",
    "assert_name",
    "assert_object",
    "ask_place",
    "ask_where",
    "follow_me",
    "look_around",
    "go_to",
    "stop",
    "answer",
)
#: ``loci.say/1`` statuses: the answer or the command's outcome, a long command started, a refusal.
SAY_STATUSES = ("ok", "accepted", "error")
_ID = string(max_length=128, description="an identifier chosen by the sender (unique per sender)")
_WORDS = string(max_length=200)
_SPEAKER = string(max_length=128, description="who speaks (a person's name, or 'tutor')")
#: A noun phrase naming what an intent is about: "the television", "a room with a couch".
TARGET = obj(
    {"head": _WORDS},
    {
        "determiner": string(choices=("the", "a"), nullable=True),
        "with": array(_WORDS, max_items=8, description="objects the referent has: 'a room with a couch'"),
        "text": string(max_length=400, description="the phrase as said"),
    },
    extra=False,
    description="a referring expression: head noun ('television', 'kitchen', 'room') and its objects",
)
_NONE = obj({}, extra=False)
#: ``args`` of each intent kind.
INTENT_ARGS: dict[str, Spec] = {
    "assert_type": obj({"type": _WORDS}, extra=False, description="'You are in the corridor'"),
    "assert_name": obj({"name": _WORDS}, extra=False, description="'I call it the recreation room'"),
    "assert_object": obj({"object": _WORDS}, extra=False, description="'This is the charging station'"),
    "ask_place": _NONE,
    "ask_where": obj({"target": TARGET}, extra=False),
    "follow_me": _NONE,
    "look_around": _NONE,
    "go_to": obj({"target": TARGET}, extra=False),
    "stop": _NONE,
    "answer": obj(
        {"answer": string(max_length=400, description="'yes', 'no', or a choice the question offered")},
        {
            "question": string(
                max_length=128, nullable=True, description="the loci.ask/1 id (none: the latest)"
            )
        },
        extra=False,
    ),
}


def _intent_checks(message: dict[str, Any]) -> str | None:
    kind = message["intent"]
    try:
        check_value(INTENT_ARGS[kind], message.get("args", {}), "args")
    except ProtocolError as exc:
        return f"{kind}: {exc}"
    return None


UTTERANCE = MessageSchema(
    "loci.utterance",
    1,
    obj(
        {"text": string(max_length=10_000)},
        {
            "stamp": _STAMP,
            "speaker": _SPEAKER,
            "id": _ID,
            "source": string(max_length=128, description="the recogniser or 'console'"),
        },
    ),
    description="something a person said (a speech recogniser's or a console's text)",
    max_bytes=SMALL_MESSAGE_BYTES,
)

INTENT = MessageSchema(
    "loci.intent",
    1,
    obj(
        {"id": _ID, "speaker": _SPEAKER, "intent": string(choices=INTENT_KINDS)},
        {
            "args": mapping(Spec("any"), description="the kind's arguments (see INTENT_ARGS)"),
            "stamp": _STAMP,
            "text": string(max_length=10_000, description="the utterance it was understood from"),
        },
    ),
    checks=(_intent_checks,),
    description="a structured request to the agent; every intent gets exactly one reply",
    max_bytes=SMALL_MESSAGE_BYTES,
)

SAY = MessageSchema(
    "loci.say",
    1,
    obj(
        {"text": string(max_length=10_000)},
        {
            "stamp": _STAMP,
            "in_reply_to": string(max_length=128, nullable=True, description="the intent this replies to"),
            "status": string(choices=SAY_STATUSES, description="default ok"),
            "reason": string(max_length=2000, nullable=True, description="why an intent was refused"),
            "task": string(
                max_length=128, nullable=True, description="the intent whose task this reports on"
            ),
            "intent": string(max_length=64, nullable=True, description="the kind of the intent replied to"),
            "to": string(max_length=128, nullable=True, description="the speaker addressed"),
            "content": mapping(
                Spec("any", nullable=True), description="the answer as data (area, objects, node, path)"
            ),
        },
    ),
    description="what the robot says: a reply to an intent, a report on a task, or a remark",
)

ASK = MessageSchema(
    "loci.ask",
    1,
    obj(
        {
            "id": _ID,
            "text": string(max_length=10_000),
            "choices": array(_WORDS, min_items=1, max_items=16, description="the answers expected"),
        },
        {
            "stamp": _STAMP,
            "in_reply_to": string(max_length=128, nullable=True, description="the intent this replies to"),
            "about": mapping(
                Spec("any", nullable=True), description="what is unclear, e.g. {kind: false_doorway, node: 7}"
            ),
            "to": string(max_length=128, nullable=True, description="the speaker addressed"),
        },
    ),
    description="a question the robot asks; answered by a loci.intent/1 'answer' naming its id",
)

#: The registry of the project's JSON messages.
SCHEMAS = SchemaRegistry([PLACE, GRAPH, AREAS, DIAGNOSTICS, ERROR, UTTERANCE, INTENT, SAY, ASK])


# ---- the (simulated) base: commands, status, ground truth --------------------------------

_POSE = {
    "x": number(description="metres"),
    "y": number(description="metres"),
    "theta": number(description="heading, radians, counter-clockwise"),
}
_WAYPOINT = obj(
    {"x": number(description="metres"), "y": number(description="metres")},
    {"theta": number(nullable=True, description="heading there, radians (the last point's: the goal's)")},
)
#: What a base can report it is doing (``loci.base_status/1``).
BASE_STATUSES = ("idle", "velocity", "route", "active", "reached", "collided", "failed", "cancelled")


def _goal_checks(message: dict[str, Any]) -> str | None:
    if message.get("cancel"):
        return None
    if (message.get("goal") is not None) == bool(message.get("path")):
        return "give either 'goal' (a pose) or 'path' (waypoints), or 'cancel': true"
    return None


TWIST = MessageSchema(
    "loci.twist",
    1,
    obj(
        {
            "v": number(minimum=-10, maximum=10, description="forward speed, m/s"),
            "omega": number(minimum=-20, maximum=20, description="turn rate, rad/s, counter-clockwise"),
        },
        {"stamp": _STAMP},
    ),
    description="a velocity command for the base (it stops when commands stop coming)",
    max_bytes=SMALL_MESSAGE_BYTES,
)

BASE_GOAL = MessageSchema(
    "loci.base_goal",
    1,
    obj(
        {},
        {
            "id": string(max_length=128, description="names the goal in status reports; repeats are ignored"),
            "stamp": _STAMP,
            "frame_id": string(choices=("odom", "map"), description="frame of the points (default odom)"),
            "goal": _WAYPOINT,
            "path": array(_WAYPOINT, min_items=1, max_items=10_000),
            "plan": boolean(description="plan around obstacles (default true); false: straight lines"),
            "cancel": boolean(description="stop whatever the base is doing"),
        },
    ),
    checks=(_goal_checks,),
    description="where the base should go: a pose, or a path of waypoints ending at the goal",
)

BASE_STATUS = MessageSchema(
    "loci.base_status",
    1,
    obj(
        {"stamp": _STAMP, "status": string(choices=BASE_STATUSES)},
        {
            "goal": string(
                max_length=128, nullable=True, description="the goal's id ('route': a scripted route)"
            ),
            "reason": string(max_length=2000, nullable=True),
            "pose": obj(_POSE, description="odometry pose (frame odom)"),
            "distance": number(minimum=0, description="metres driven so far"),
        },
    ),
    description="what the base does: a goal became active, was reached, failed, or the base collided",
    max_bytes=SMALL_MESSAGE_BYTES,
)

TRUTH = MessageSchema(
    "loci.truth",
    1,
    obj(
        {"stamp": _STAMP, **_POSE},
        {
            "frame_id": string(max_length=64),
            "odom": obj(_POSE, description="the odometry pose at the same instant"),
            "space": integer(minimum=0, description="the building's space id there (0: none)"),
            "label": string(max_length=64, nullable=True, description="the place class there"),
            "collisions": integer(minimum=0),
        },
    ),
    description="the simulated robot's true pose (frame map) and place class, for evaluation only",
)

for _schema in (TWIST, BASE_GOAL, BASE_STATUS, TRUTH):
    SCHEMAS.register(_schema)


# ---- people, objects, concepts (the conceptual map) ------------------------------------------

_XY = array(number(), min_items=2, max_items=2, description="[x, y] metres")

PEOPLE = MessageSchema(
    "loci.people",
    1,
    obj(
        {
            "stamp": _STAMP,
            "legs": array(_XY, description="leg centroids, tracking frame"),
            "people": array(obj({"x": number(), "y": number(), "legs": integer(minimum=0, maximum=2)})),
            "tracks": array(
                obj(
                    {"id": integer(minimum=0), "x": number(), "y": number()},
                    {
                        "vx": number(description="m/s"),
                        "vy": number(description="m/s"),
                        "misses": integer(minimum=0),
                        "age": integer(minimum=0),
                    },
                )
            ),
        },
        {"frame_id": string(max_length=64, description="the tracking frame (odom, or the laser's)")},
    ),
    description="people in one laser scan: legs, persons (leg pairs) and confirmed tracks",
)

_AREA_ID = integer(minimum=0)
_OBJECT_REF = obj({"name": _WORDS}, {"kind": string(max_length=200, nullable=True)})

OBJECTS = MessageSchema(
    "loci.objects",
    1,
    obj(
        {
            "stamp": _STAMP,
            "recognitions": array(
                obj(
                    {"name": _WORDS, "kind": string(max_length=200, nullable=True), "score": number()},
                    {
                        "node": integer(minimum=0, nullable=True, description="the node it was seen from"),
                        "area": integer(minimum=0, nullable=True, description="the area it was seen from"),
                        "inliers": integer(minimum=0),
                        "bearing": number(nullable=True, description="radians, left of the camera axis"),
                    },
                )
            ),
        },
        {"frame_id": string(max_length=64)},
    ),
    description="the object instances the camera recognised in one frame",
)


def _concepts_checks(message: dict[str, Any]) -> str | None:
    for key, area in message["areas"].items():
        if not isinstance(area, dict):
            return f"areas.{key}: expected an object"
        if "id" in area and str(area["id"]) != str(key):
            return f"areas.{key}: its 'id' is {area['id']!r}"
    return None


CONCEPT_AREA = obj(
    {},
    {
        "id": _AREA_ID,
        "class": string(max_length=64, nullable=True, description="room, corridor, hallway (or None)"),
        "types": array(string(max_length=200), description="ontology classes, most specific first"),
        "names": array(_WORDS, description="what people called it"),
        "objects": array(_OBJECT_REF),
        "asserted": Spec("any", description="what people said (types, names, by speaker)"),
        "inferred": Spec("any", description="what the reasoner inferred"),
    },
    description="an area of the conceptual map (keys as in a loci.say/1 AREA)",
)

CONCEPTS = MessageSchema(
    "loci.concepts",
    1,
    obj(
        {
            "areas": mapping(CONCEPT_AREA, description="area id (a string) → the area"),
            "objects": mapping(
                Spec("any", nullable=True), description="object name → {name, kind, area, node, ...}"
            ),
        },
        {"version": integer(minimum=0), "stamp": _STAMP},
    ),
    checks=(_concepts_checks,),
    description="the conceptual map: areas with their classes, types, names and objects",
)

#: What a ``loci.map_edit/1`` can do to the map.
MAP_EDIT_OPS = ("remove_doorway",)

MAP_EDIT = MessageSchema(
    "loci.map_edit",
    1,
    obj(
        {
            "op": string(choices=MAP_EDIT_OPS),
            "node": integer(minimum=0, description="the navigation node concerned"),
            "after_scan": number(
                nullable=True,
                description="the stamp of the last scan processed before the edit (none: before any)",
            ),
        },
        {
            "stamp": _STAMP,
            "reason": string(max_length=400, description="why, e.g. the answer to 'Was there a door here?'"),
        },
    ),
    description="a change of the map that scans do not explain (the tutor said a doorway was none)",
    max_bytes=SMALL_MESSAGE_BYTES,
)

for _schema in (PEOPLE, OBJECTS, CONCEPTS, MAP_EDIT):
    SCHEMAS.register(_schema)


# ---- the guided-tour demo's simulated tutor (demo keys: loci/<r>/sim/tutor, .../state) --------

_WAYPOINTS = array(array(number(), min_items=2, max_items=2), min_items=1, description="[[x, y], ...] metres")


def _tutor_cmd_checks(message: dict[str, Any]) -> str | None:
    if message.get("stop") is True:
        return None
    walk = message.get("walk")
    if isinstance(walk, str) and walk:
        return None
    if isinstance(walk, list):
        try:
            check_value(_WAYPOINTS, walk, "walk")
        except ProtocolError as exc:
            return f"a waypoint is [x, y] in metres (finite numbers): {exc}"
        return None
    return 'a tutor command is {"walk": LEG NAME or [[x, y], ...]} or {"stop": true}'


TUTOR_CMD = MessageSchema(
    "loci.tutor_cmd",
    1,
    obj({}, {"walk": Spec("any", description="a leg's name, or waypoints [[x, y], ...]"), "stop": boolean()}),
    checks=(_tutor_cmd_checks,),
    description="the demo to the simulated tutor: walk a leg of the tour or waypoints, or stop",
    max_bytes=SMALL_MESSAGE_BYTES,
)
TUTOR_STATE = MessageSchema(
    "loci.tutor_state",
    1,
    obj(
        {
            "x": number(description="metres, map frame"),
            "y": number(description="metres, map frame"),
            "heading": number(description="radians"),
            "walking": boolean(),
            "waiting": boolean(description="waits for the robot to catch up"),
            "remaining": number(minimum=0, description="metres left of the walk"),
            "walks": integer(minimum=0, description="walks finished"),
        }
    ),
    description="the simulated tutor's body and walk, a few times a second (demo only)",
)
for _schema in (TUTOR_CMD, TUTOR_STATE):
    SCHEMAS.register(_schema)

# ---- localization ----------------------------------------------------------------------------

LOCALIZED_POSE = MessageSchema(
    "loci.pose",
    1,
    obj(
        {
            "stamp": _STAMP,
            "frame_id": string(max_length=64, description="the map's frame ('map')"),
            **_POSE,
            "covariance": array(
                number(),
                min_items=9,
                max_items=9,
                description="3x3 row-major covariance of x, y, theta (m², rad²)",
            ),
        },
        {
            "mode": string(max_length=32, description="'global', 'tracking' or 'matching'"),
            "share": number(
                minimum=0, maximum=1, description="the estimate's cluster's share of the particles' weight"
            ),
            "particles": integer(minimum=0),
            "map_to_odom": obj(_POSE, description="the map -> odom transform at this stamp"),
        },
    ),
    description="the robot's pose in a known map with its covariance (loci localize, [localization])",
)

LOCALIZATION = MessageSchema(
    "loci.localization",
    1,
    obj(
        {
            "stamp": _STAMP,
            "state": string(choices=("tracking", "uncertain", "lost"), description="how sure the pose is"),
            "sigma": number(minimum=0, description="metres the pose may be off (one standard deviation)"),
            "sigma_theta": number(minimum=0, description="radians the heading may be off"),
        },
        {
            "fit": number(minimum=0, maximum=1, description="the scan's match fit"),
            "event": string(
                nullable=True,
                max_length=32,
                description="'correction' (larger than the odometry allows), 'reverted' (one undone), "
                "'stall', 'resumed' (the odometry stood still, moved again)",
            ),
            "deviation": number(
                minimum=0, description="metres the pose moved from the odometry's prediction"
            ),
            "deviation_theta": number(minimum=0, description="radians likewise"),
            "pose": obj(_POSE, description="the corrected pose of the laser (map frame)"),
        },
    ),
    description="the pose tracker's confidence, when it changes or something happens ([localization])",
    max_bytes=SMALL_MESSAGE_BYTES,
)

for _schema in (LOCALIZED_POSE, LOCALIZATION):
    SCHEMAS.register(_schema)

# ---- saving the map (loci/<r>/map/save, agent/core/map_files.py) -----------------------------

_FOLDER = string(max_length=4096, description="an absolute path on the agent's computer")

MAP_SAVE = MessageSchema(
    "loci.map_save",
    1,
    obj(
        {"dir": _FOLDER},
        {
            "overwrite": boolean(description="replace a map saved there before (default: refuse)"),
            "stamp": _STAMP,
        },
    ),
    description="a request to the agent: save the occupancy map and its place labels in a folder",
    max_bytes=SMALL_MESSAGE_BYTES,
)

MAP_SAVED = MessageSchema(
    "loci.map_saved",
    1,
    obj(
        {
            "stamp": _STAMP,
            "dir": _FOLDER,
            "files": array(string(max_length=4096), description="the files written, full paths"),
            "frame_id": string(
                max_length=64, description="the map's frame: 'map' with tracking, else 'odom'"
            ),
            "resolution": number(minimum=0, description="metres per cell"),
            "origin": array(
                number(), min_items=3, max_items=3, description="[x, y, yaw] of the map's lower-left corner"
            ),
            "width": integer(minimum=1, description="cells"),
            "height": integer(minimum=1, description="cells"),
            "scans": integer(minimum=0, description="scans integrated into the map"),
        }
    ),
    description="the agent's answer to loci.map_save/1: where the map was saved, its size and frame",
)

for _schema in (MAP_SAVE, MAP_SAVED):
    SCHEMAS.register(_schema)
