"""Messages on the wire, defined once for Zenoh and MCAP alike.

Sensor streams use the Foxglove protobuf schemas so the Foxglove app shows them:

==========================  ==========================  ==========================
our type                    wire schema                 notes
==========================  ==========================  ==========================
``drivers.LaserScan``       ``foxglove.LaserScan``      ranges/intensities as doubles
``drivers.Pose2D``          ``foxglove.PoseInFrame``    heading as a z-rotation quaternion
``drivers.CameraFrame``     ``foxglove.CompressedImage``  format ``"jpeg"``
(graph, areas)              ``foxglove.SceneUpdate``    built by :mod:`agent.bus.scene`
``frame_transform(pose)``   ``foxglove.FrameTransform``  odom → laser, for Foxglove
==========================  ==========================  ==========================

The last two are for viewing only: they are encoded, never decoded.

Every decoder checks the payload's size before parsing (:data:`MAX_SCAN_BYTES`,
:data:`MAX_POSE_BYTES`, :data:`MAX_FRAME_BYTES`; JSON: :mod:`agent.bus.schemas`) and raises
:class:`ProtocolError`, never another exception, on any input
(``python -m tools.fuzz``, docs/results/reliability.md).

Fields Foxglove has no slot for travel as extra protobuf fields numbered from 1001, which
protobuf readers (Foxglove's included) skip: a scan's ``seq`` (1001, varint), ``range_min``
(1002), ``range_max`` (1003), ``scan_time`` (1004) and the exact ``angle_increment`` (1005,
doubles), and a camera frame's ``seq`` (1001). A scan from another source without them gets
``angle_increment = (end - start) / (n - 1)`` and ``range_max`` = its largest finite range.

Encoding uses the Foxglove SDK (so the bytes are Foxglove's own); decoding parses the wire
format (:mod:`agent.bus.protowire`) because the SDK cannot decode. JSON streams use
:mod:`agent.bus.schemas`. A :class:`Codec` names the schema, its Zenoh encoding
(``application/protobuf;foxglove.LaserScan``, ``application/json;loci.place/1``) and its MCAP
schema; :func:`codec_for` finds one by schema name.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any, Generic, TypeVar

import numpy as np
from foxglove import messages as fg

from agent.bus import protowire as pw
from agent.bus.schemas import SCHEMAS, SchemaRegistry
from drivers.messages import CameraFrame, LaserScan, Pose2D
from knowledge.errors import ProtocolError

T = TypeVar("T")

LASER_SCAN = "foxglove.LaserScan"
POSE_IN_FRAME = "foxglove.PoseInFrame"
COMPRESSED_IMAGE = "foxglove.CompressedImage"
SCENE_UPDATE = "foxglove.SceneUpdate"
FRAME_TRANSFORM = "foxglove.FrameTransform"

#: Zenoh encodings (the part before ``;``) of the two payload families.
PROTOBUF_ENCODING = "application/protobuf"
JSON_ENCODING = "application/json"

#: Largest payloads the decoders accept, bytes, checked before parsing: a scan of 65,535
#: doubles (and as many intensities) is about 1 MiB, a pose about 100 bytes; a camera frame is
#: limited again by the camera's size (:func:`drivers.camera.jpeg.decode_image`).
MAX_SCAN_BYTES = 2 * 1024 * 1024
MAX_POSE_BYTES = 64 * 1024
MAX_FRAME_BYTES = 16 * 1024 * 1024

# our extra protobuf field numbers (see the module docstring)
_SEQ, _RANGE_MIN, _RANGE_MAX, _SCAN_TIME, _ANGLE_INC = 1001, 1002, 1003, 1004, 1005


@dataclass(frozen=True)
class McapSchema:
    """How a payload is described in an MCAP file.

    Attributes:
        name: the schema record's name (``foxglove.LaserScan``, ``loci.place/1``).
        encoding: the schema record's encoding (``protobuf`` or ``jsonschema``).
        data: the schema itself (a FileDescriptorSet, or a JSON Schema document).
        message_encoding: the channel's message encoding (``protobuf`` or ``json``).
    """

    name: str
    encoding: str
    data: bytes
    message_encoding: str


@dataclass(frozen=True)
class Codec(Generic[T]):
    """Encoder and decoder of one payload schema.

    ``decode`` raises :class:`ProtocolError` (only) for bytes that are not a valid message.
    """

    schema: str
    family: str  # "protobuf" or "json"
    encode: Callable[[T], bytes]
    decode: Callable[[bytes], T]

    @property
    def zenoh_encoding(self) -> str:
        """The Zenoh encoding string, ``<mime>;<schema>``."""
        mime = PROTOBUF_ENCODING if self.family == "protobuf" else JSON_ENCODING
        return f"{mime};{self.schema}"

    def mcap_schema(self) -> McapSchema:
        found = mcap_schema_for(self.schema)
        assert found is not None
        return found


# ---- time --------------------------------------------------------------------------------


def _timestamp(stamp: float) -> fg.Timestamp:
    if not (math.isfinite(stamp) and stamp >= 0):
        raise ValueError(f"a stamp must be finite seconds since the epoch (>= 0), got {stamp}")
    sec = math.floor(stamp)
    nsec = round((stamp - sec) * 1e9)
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return fg.Timestamp(int(sec), int(nsec))


def _check_size(data: bytes, limit: int, what: str) -> None:
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ProtocolError(f"{what}: a payload must be bytes, got {type(data).__name__}")
    if len(data) > limit:
        raise ProtocolError(f"{what}: payload of {len(data)} bytes exceeds {limit}")


def _read_timestamp(raw: bytes) -> float:
    f = pw.fields_by_number(raw)
    sec = pw.last_int64(f, 1, "timestamp.seconds")
    nsec = pw.last_int64(f, 2, "timestamp.nanos")
    if not 0 <= nsec < 1_000_000_000:
        raise ProtocolError(f"protobuf: timestamp nanos {nsec} out of range [0, 1e9)")
    return sec + nsec * 1e-9


_IDENTITY_POSE = fg.Pose(
    position=fg.Vector3(x=0.0, y=0.0, z=0.0), orientation=fg.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
)


# ---- LaserScan ---------------------------------------------------------------------------


def encode_laser_scan(scan: LaserScan) -> bytes:
    """A :class:`LaserScan` as ``foxglove.LaserScan`` bytes (plus our fields 1001-1005)."""
    msg = fg.LaserScan(
        timestamp=_timestamp(scan.stamp),
        frame_id=scan.frame_id,
        pose=_IDENTITY_POSE,
        start_angle=float(scan.angle_min),
        end_angle=float(scan.angle_max),
        ranges=scan.ranges.astype(np.float64).tolist(),
        intensities=[] if scan.intensities is None else scan.intensities.astype(np.float64).tolist(),
    )
    return b"".join(
        (
            msg.encode(),
            pw.encode_varint_field(_SEQ, int(scan.seq)),
            pw.encode_double_field(_RANGE_MIN, float(scan.range_min)),
            pw.encode_double_field(_RANGE_MAX, float(scan.range_max)),
            pw.encode_double_field(_SCAN_TIME, float(scan.scan_time)),
            pw.encode_double_field(_ANGLE_INC, float(scan.angle_increment)),
        )
    )


def decode_laser_scan(data: bytes) -> LaserScan:
    """``foxglove.LaserScan`` bytes as a :class:`LaserScan` (the sensor pose is not kept)."""
    _check_size(data, MAX_SCAN_BYTES, LASER_SCAN)
    f = pw.fields_by_number(data)
    stamp = _read_timestamp(pw.last_bytes(f, 1, "timestamp"))
    frame_id = pw.last_string(f, 2, "frame_id")
    start = pw.last_double(f, 4, "start_angle")
    end = pw.last_double(f, 5, "end_angle")
    ranges = pw.repeated_doubles(f, 6, "ranges")
    intens = pw.repeated_doubles(f, 7, "intensities")
    n = ranges.shape[0]
    if n == 0:
        raise ProtocolError("foxglove.LaserScan: no ranges")
    if intens.shape[0] not in (0, n):
        raise ProtocolError(f"foxglove.LaserScan: {intens.shape[0]} intensities for {n} ranges")
    inc = pw.last_double(f, _ANGLE_INC, "angle_increment") if _ANGLE_INC in f else None
    if inc is None:
        if n < 2:
            raise ProtocolError("foxglove.LaserScan: one beam and no angle increment")
        inc = (end - start) / (n - 1)
    if _RANGE_MAX in f:
        range_max = pw.last_double(f, _RANGE_MAX, "range_max")
    else:
        finite = ranges[np.isfinite(ranges)]
        range_max = float(finite.max()) if finite.size else 0.0
    try:
        return LaserScan(
            stamp=stamp,
            seq=pw.last_varint(f, _SEQ, "seq"),
            frame_id=frame_id,
            angle_min=start,
            angle_increment=inc,
            range_max=range_max,
            ranges=ranges,
            intensities=intens if intens.shape[0] else None,
            range_min=pw.last_double(f, _RANGE_MIN, "range_min"),
            scan_time=pw.last_double(f, _SCAN_TIME, "scan_time"),
        )
    except ValueError as exc:
        raise ProtocolError(f"foxglove.LaserScan: {exc}") from exc


# ---- Pose2D ------------------------------------------------------------------------------


def encode_pose(pose: Pose2D) -> bytes:
    """A :class:`Pose2D` as ``foxglove.PoseInFrame`` (z = 0, rotation about z by theta)."""
    half = 0.5 * pose.theta
    msg = fg.PoseInFrame(
        timestamp=_timestamp(pose.stamp),
        frame_id=pose.frame_id,
        pose=fg.Pose(
            position=fg.Vector3(x=float(pose.x), y=float(pose.y), z=0.0),
            orientation=fg.Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)),
        ),
    )
    return msg.encode()


def decode_pose(data: bytes) -> Pose2D:
    """``foxglove.PoseInFrame`` bytes as a :class:`Pose2D` (x, y and the yaw of the rotation)."""
    _check_size(data, MAX_POSE_BYTES, POSE_IN_FRAME)
    f = pw.fields_by_number(data)
    stamp = _read_timestamp(pw.last_bytes(f, 1, "timestamp"))
    frame_id = pw.last_string(f, 2, "frame_id")
    pose = pw.fields_by_number(pw.last_bytes(f, 3, "pose"))
    pos = pw.fields_by_number(pw.last_bytes(pose, 1, "pose.position"))
    rot = pw.fields_by_number(pw.last_bytes(pose, 2, "pose.orientation"))
    qx, qy, qz, qw = (pw.last_double(rot, i, f"pose.orientation.{c}") for i, c in enumerate("xyzw", 1))
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    try:
        return Pose2D(
            x=pw.last_double(pos, 1, "pose.position.x"),
            y=pw.last_double(pos, 2, "pose.position.y"),
            theta=yaw,
            stamp=stamp,
            frame_id=frame_id,
        )
    except ValueError as exc:
        raise ProtocolError(f"foxglove.PoseInFrame: {exc}") from exc


# ---- CameraFrame -------------------------------------------------------------------------


def encode_camera_frame(frame: CameraFrame, quality: int = 90) -> bytes:
    """A :class:`CameraFrame` as ``foxglove.CompressedImage`` (its JPEG, or the image encoded)."""
    jpeg = frame.jpeg
    if jpeg is None:
        import cv2

        assert frame.image is not None
        ok, buf = cv2.imencode(".jpg", frame.image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:
            raise ValueError(f"cannot encode a {frame.image.shape} image as JPEG")
        jpeg = buf.tobytes()
    msg = fg.CompressedImage(
        timestamp=_timestamp(frame.stamp), frame_id=frame.frame_id, data=jpeg, format="jpeg"
    )
    return msg.encode() + pw.encode_varint_field(_SEQ, int(frame.seq))


def decode_camera_frame(data: bytes) -> CameraFrame:
    """``foxglove.CompressedImage`` (JPEG) bytes as a :class:`CameraFrame` carrying the JPEG."""
    _check_size(data, MAX_FRAME_BYTES, COMPRESSED_IMAGE)
    f = pw.fields_by_number(data)
    fmt = pw.last_string(f, 3, "format").lower()
    if fmt not in ("jpeg", "jpg"):
        raise ProtocolError(f"foxglove.CompressedImage: format {fmt!r} is not supported (only jpeg)")
    jpeg = pw.last_bytes(f, 2, "data")
    if not jpeg:
        raise ProtocolError("foxglove.CompressedImage: no image data")
    return CameraFrame(
        stamp=_read_timestamp(pw.last_bytes(f, 1, "timestamp")),
        seq=pw.last_varint(f, _SEQ, "seq"),
        frame_id=pw.last_string(f, 4, "frame_id"),
        jpeg=jpeg,
    )


# ---- JSON --------------------------------------------------------------------------------


def json_codec(schema_id: str, registry: SchemaRegistry = SCHEMAS) -> Codec[dict[str, Any]]:
    """The codec of a versioned JSON message (validated both ways)."""
    registry.get(schema_id)  # unknown ids fail now, not on the first message

    def encode(message: dict[str, Any]) -> bytes:
        return registry.encode(message, schema_id)

    def decode(data: bytes) -> dict[str, Any]:
        return registry.decode(data, schema_id)

    return Codec(schema_id, "json", encode, decode)


def frame_transform(pose: Pose2D, child_frame_id: str) -> fg.FrameTransform:
    """The transform placing ``child_frame_id`` (e.g. the laser) at ``pose`` in ``pose.frame_id``.

    Foxglove's 3D panel needs it to draw scans (frame ``laser``) in the odometry frame.
    """
    half = 0.5 * pose.theta
    return fg.FrameTransform(
        timestamp=_timestamp(pose.stamp),
        parent_frame_id=pose.frame_id,
        child_frame_id=child_frame_id,
        translation=fg.Vector3(x=float(pose.x), y=float(pose.y), z=0.0),
        rotation=fg.Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)),
    )


def _encode_foxglove(message: Any) -> bytes:
    return bytes(message.encode())


def _no_decode(data: bytes) -> Any:
    raise ProtocolError("scene updates and transforms are for viewing only; they are not decoded")


LASER_SCAN_CODEC: Codec[LaserScan] = Codec(LASER_SCAN, "protobuf", encode_laser_scan, decode_laser_scan)
POSE_CODEC: Codec[Pose2D] = Codec(POSE_IN_FRAME, "protobuf", encode_pose, decode_pose)
CAMERA_CODEC: Codec[CameraFrame] = Codec(
    COMPRESSED_IMAGE, "protobuf", encode_camera_frame, decode_camera_frame
)
SCENE_CODEC: Codec[fg.SceneUpdate] = Codec(SCENE_UPDATE, "protobuf", _encode_foxglove, _no_decode)
TRANSFORM_CODEC: Codec[fg.FrameTransform] = Codec(FRAME_TRANSFORM, "protobuf", _encode_foxglove, _no_decode)

_PROTOBUF_CODECS: dict[str, Codec[Any]] = {
    c.schema: c for c in (LASER_SCAN_CODEC, POSE_CODEC, CAMERA_CODEC, SCENE_CODEC, TRANSFORM_CODEC)
}
_FOXGLOVE_TYPES: dict[str, Any] = {
    LASER_SCAN: fg.LaserScan,
    POSE_IN_FRAME: fg.PoseInFrame,
    COMPRESSED_IMAGE: fg.CompressedImage,
    SCENE_UPDATE: fg.SceneUpdate,
    FRAME_TRANSFORM: fg.FrameTransform,
}


def codec_for(schema: str, registry: SchemaRegistry = SCHEMAS) -> Codec[Any]:
    """The codec of a schema name: a Foxglove type or a registered JSON schema id."""
    if schema in _PROTOBUF_CODECS:
        return _PROTOBUF_CODECS[schema]
    if schema in registry:
        return json_codec(schema, registry)
    raise ValueError(f"no codec for schema {schema!r}: use a foxglove.* type or a registered loci.*/N id")


def split_encoding(encoding: str) -> tuple[str, str]:
    """``"application/json;loci.place/1"`` → ``("application/json", "loci.place/1")``."""
    mime, _, schema = encoding.partition(";")
    return mime.strip(), schema.strip()


def checked_decode(codec: Codec[T], encoding: str, payload: bytes, where: str) -> T:
    """Decode a sample as a subscriber does: a sample whose encoding names another schema
    is invalid (:class:`ProtocolError`); one without a schema is decoded anyway."""
    _, schema = split_encoding(encoding)
    if schema and schema != codec.schema:
        raise ProtocolError(f"{where}: expected {codec.schema}, the sample says {schema}")
    return codec.decode(payload)


@cache
def _foxglove_mcap_schema(name: str) -> McapSchema:
    s = _FOXGLOVE_TYPES[name].get_schema()
    return McapSchema(s.name, s.encoding, bytes(s.data), "protobuf")


def mcap_schema_for(schema: str, registry: SchemaRegistry = SCHEMAS) -> McapSchema | None:
    """The MCAP schema of a schema name (Foxglove type or JSON schema id), None if unknown.

    Foxglove types carry their FileDescriptorSet (schema encoding ``protobuf``); JSON
    messages carry their JSON Schema (schema encoding ``jsonschema``, messages ``json``).
    """
    if schema in _FOXGLOVE_TYPES:
        return _foxglove_mcap_schema(schema)
    if schema in registry:
        import json

        doc = registry.get(schema).json_schema()
        return McapSchema(schema, "jsonschema", json.dumps(doc, indent=1).encode("utf-8"), "json")
    return None
