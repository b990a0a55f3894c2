"""ROS 2 messages as CDR bytes, through ``rosbags`` (its CDR serialiser and its RIHS01 type hashes).

The type definitions are those of ROS 2 Jazzy shipped with ``rosbags`` (:data:`TYPESTORE`);
``sensor_msgs/LaserScan``, ``nav_msgs/Odometry``, ``tf2_msgs/TFMessage``, ``std_msgs/String``
and ``visualization_msgs/MarkerArray`` have not changed since Humble, so their CDR is the
same on Humble, Iron, Jazzy and Kilted; the type hashes (REP 2016) exist from Iron on.

* :func:`decode`: CDR bytes → a ``rosbags`` message object (:class:`ProtocolError` when the
  bytes are not such a message);
* :func:`make`: a message object of any type with every field not given set to its
  zero value (ROS's own default);
* :func:`place_string`: the ``loci.place/1`` message as ``std_msgs/String`` (its JSON);
* :func:`graph_markers`: the graph and areas as ``visualization_msgs/MarkerArray`` (a
  ``DELETEALL`` first, so vanished nodes vanish in RViz and Foxglove too; the nodes as one
  ``SPHERE_LIST`` coloured by class, the edges as a ``LINE_LIST``, each area's class, id and
  names as a ``TEXT_VIEW_FACING``);
* :func:`attachment`: rmw_zenoh's per-sample attachment (sequence number, source timestamp,
  the publisher's 16-byte GID), serialised with Zenoh's own serialiser as rmw_zenoh does.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from functools import cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

from agent.bus.scene import class_rgba
from knowledge.errors import ProtocolError

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STRING = "std_msgs/msg/String"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"

#: The message definitions (ROS 2 Jazzy, as ``rosbags`` ships them).
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

_NUMPY = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8,
    "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
    "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64,
}  # fmt: skip


@cache
def type_hash(ros_type: str) -> str:
    """The REP-2016 ``RIHS01_…`` hash of a message type."""
    return str(TYPESTORE.hash_rihs01(ros_type))


def decode(data: bytes, ros_type: str) -> Any:
    """CDR bytes as a message object of ``ros_type``.

    Raises:
        ProtocolError: the bytes are not a CDR ``ros_type`` (naming the type and why).
    """
    if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
        raise ProtocolError(f"{ros_type}: not CDR (the 4-byte encapsulation header is missing)")
    try:
        return TYPESTORE.deserialize_cdr(data, ros_type)
    except Exception as exc:  # rosbags raises struct, index and value errors on bad bytes
        raise ProtocolError(f"{ros_type}: {len(data)} bytes that are not a CDR {ros_type}: {exc}") from exc


def encode(message: Any) -> bytes:
    """A message object as CDR bytes (little endian, with the encapsulation header)."""
    return bytes(TYPESTORE.serialize_cdr(message, message.__msgtype__))


def _default(desc: tuple[Any, Any]) -> Any:
    kind, spec = desc
    name = getattr(kind, "name", str(kind))
    if name == "BASE":
        base = spec[0]
        return "" if base == "string" else (False if base == "bool" else _NUMPY[base](0).item())
    if name == "NAME":
        return make(spec)
    sub, length = spec
    sub_name = getattr(sub[0], "name", str(sub[0]))
    if sub_name == "BASE" and sub[1][0] in _NUMPY:
        return np.zeros(length if name == "ARRAY" else 0, dtype=_NUMPY[sub[1][0]])
    return [_default(sub) for _ in range(length if name == "ARRAY" else 0)]


def make(ros_type: str, **fields: Any) -> Any:
    """A message of ``ros_type``: ``fields`` as given, every other field at its zero value."""
    _, defs = TYPESTORE.fielddefs[ros_type]
    values = {name: fields[name] if name in fields else _default(desc) for name, desc in defs}
    unknown = set(fields) - set(values)
    if unknown:
        raise ValueError(f"{ros_type} has no field {sorted(unknown)[0]!r}")
    return TYPESTORE.types[ros_type](**values)


def time_msg(stamp: float) -> Any:
    sec = math.floor(stamp)
    return make(
        "builtin_interfaces/msg/Time", sec=int(sec), nanosec=min(999_999_999, round((stamp - sec) * 1e9))
    )


def header(stamp: float, frame_id: str) -> Any:
    return make("std_msgs/msg/Header", stamp=time_msg(stamp), frame_id=frame_id)


def place_string(place: Mapping[str, Any]) -> bytes:
    """``std_msgs/String`` CDR carrying the ``loci.place/1`` message as compact JSON."""
    return encode(make(STRING, data=json.dumps(place, separators=(",", ":"), sort_keys=True)))


def _point(x: float, y: float, z: float = 0.0) -> Any:
    return make("geometry_msgs/msg/Point", x=float(x), y=float(y), z=float(z))


def _color(rgba: Sequence[float]) -> Any:
    r, g, b, a = (float(v) for v in rgba)
    return make("std_msgs/msg/ColorRGBA", r=r, g=g, b=b, a=a)


def _pose(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return make(
        "geometry_msgs/msg/Pose",
        position=_point(x, y, z),
        orientation=make("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
    )


def graph_markers(
    graph: Mapping[str, Any],
    areas: Mapping[str, Any],
    *,
    stamp: float,
    frame_id: str = "odom",
    names: Mapping[int, Sequence[str]] | None = None,
    node_size: float = 0.25,
) -> bytes:
    """The graph and the areas as ``visualization_msgs/MarkerArray`` CDR (see the module docstring)."""
    hdr = header(stamp, frame_id)
    markers = [make("visualization_msgs/msg/Marker", header=hdr, ns="loci", id=0, action=3)]
    nodes = list(graph.get("nodes", ()))
    if nodes:
        markers.append(
            make(
                "visualization_msgs/msg/Marker",
                header=hdr,
                ns="loci/graph/nodes",
                id=1,
                type=7,  # SPHERE_LIST
                pose=_pose(),
                scale=make("geometry_msgs/msg/Vector3", x=node_size, y=node_size, z=node_size),
                color=_color((1, 1, 1, 1)),
                points=[_point(n["x"], n["y"]) for n in nodes],
                colors=[
                    _color(class_rgba("doorway" if n.get("kind") == "doorway" else n.get("label")))
                    for n in nodes
                ],
            )
        )
    pos = {int(n["id"]): (float(n["x"]), float(n["y"])) for n in nodes}
    ends = [pos[int(i)] for edge in graph.get("edges", ()) for i in edge if all(int(j) in pos for j in edge)]
    if ends:
        markers.append(
            make(
                "visualization_msgs/msg/Marker",
                header=hdr,
                ns="loci/graph/edges",
                id=2,
                type=5,  # LINE_LIST
                pose=_pose(),
                scale=make("geometry_msgs/msg/Vector3", x=0.04, y=0.0, z=0.0),
                color=_color((0.2, 0.2, 0.2, 1.0)),
                points=[_point(x, y) for x, y in ends],
            )
        )
    for area in areas.get("areas", ()):
        xy = [pos[int(n)] for n in area.get("nodes", ()) if int(n) in pos]
        if not xy:
            continue
        text = f"{area.get('label') or '?'} #{area['id']}"
        if names and names.get(int(area["id"])):
            text += "\n" + ", ".join(names[int(area["id"])])
        markers.append(
            make(
                "visualization_msgs/msg/Marker",
                header=hdr,
                ns="loci/areas",
                id=100 + int(area["id"]),
                type=9,  # TEXT_VIEW_FACING
                pose=_pose(sum(p[0] for p in xy) / len(xy), sum(p[1] for p in xy) / len(xy), 1.0),
                scale=make("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.5),
                color=_color(class_rgba(area.get("label"))),
                text=text,
            )
        )
    return encode(make(MARKER_ARRAY, markers=markers))


def attachment(sequence: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's attachment of a published sample: int64 sequence number, int64 source
    timestamp (ns), the publisher's 16-byte GID, in Zenoh's serialisation (a fixed-size
    array is its elements without a length, as zenoh-ext serialises tuples)."""
    from zenoh.ext import Int64, UInt8, z_serialize

    if len(gid) != 16:
        raise ValueError(f"a GID is 16 bytes, got {len(gid)}")
    return bytes(
        z_serialize((Int64(sequence), Int64(source_timestamp_ns), tuple(UInt8(b) for b in gid))).to_bytes()
    )
