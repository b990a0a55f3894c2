"""Codecs: our messages ↔ Foxglove protobuf, checked against the Foxglove SDK's own schemas."""

from __future__ import annotations

import contextlib
import math

import cv2
import numpy as np
import pytest
from foxglove import messages as fg
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.bus import codecs
from agent.bus import protowire as pw
from agent.bus.scene import areas_scene, class_rgba, graph_scene
from drivers.messages import CameraFrame, LaserScan, Pose2D
from knowledge.errors import ProtocolError


def _message_fields(schema_data: bytes) -> dict[str, dict[str, int]]:
    """Message name → {field name: number}, read from a FileDescriptorSet (independent of codecs)."""
    out: dict[str, dict[str, int]] = {}
    for _, _, file_proto in pw.iter_fields(schema_data):
        assert isinstance(file_proto, bytes)
        fd = pw.fields_by_number(file_proto)
        package = pw.last_string(fd, 2, "package")
        for _, msg in fd.get(4, []):
            assert isinstance(msg, bytes)
            m = pw.fields_by_number(msg)
            numbers = {}
            for _, f in m.get(2, []):
                assert isinstance(f, bytes)
                ff = pw.fields_by_number(f)
                numbers[pw.last_string(ff, 1, "name")] = pw.last_varint(ff, 3, "number")
            out[f"{package}.{pw.last_string(m, 1, 'name')}"] = numbers
    return out


def _scan(n: int = 361, intensities: bool = False, seq: int = 7) -> LaserScan:
    rng = np.random.default_rng(n)
    return LaserScan(
        stamp=1_700_000_000.25,
        seq=seq,
        frame_id="laser",
        angle_min=-math.pi / 2,
        angle_increment=math.pi / (n - 1) if n > 1 else 0.01,
        range_max=8.0,
        ranges=rng.uniform(0.05, 8.0, n).astype(np.float32),
        intensities=rng.uniform(0, 255, n).astype(np.float32) if intensities else None,
        range_min=0.05,
        scan_time=1 / 37.5,
    )


def test_field_numbers_match_the_foxglove_schemas() -> None:
    scan = _message_fields(fg.LaserScan.get_schema().data)["foxglove.LaserScan"]
    assert (scan["timestamp"], scan["frame_id"], scan["start_angle"], scan["end_angle"]) == (1, 2, 4, 5)
    assert (scan["ranges"], scan["intensities"]) == (6, 7)
    # our extension numbers must not collide with Foxglove's fields
    assert all(n < 1001 for n in scan.values())
    pose = _message_fields(fg.PoseInFrame.get_schema().data)
    assert pose["foxglove.PoseInFrame"] == {"timestamp": 1, "frame_id": 2, "pose": 3}
    assert pose["foxglove.Pose"] == {"position": 1, "orientation": 2}
    assert pose["foxglove.Quaternion"] == {"x": 1, "y": 2, "z": 3, "w": 4}
    image = _message_fields(fg.CompressedImage.get_schema().data)["foxglove.CompressedImage"]
    assert image == {"timestamp": 1, "frame_id": 4, "data": 2, "format": 3}


@pytest.mark.parametrize("intensities", [False, True])
def test_laser_scan_round_trip(intensities: bool) -> None:
    scan = _scan(intensities=intensities)
    back = codecs.decode_laser_scan(codecs.encode_laser_scan(scan))
    assert back.stamp == pytest.approx(scan.stamp, abs=1e-6)
    assert (back.seq, back.frame_id) == (scan.seq, scan.frame_id)
    assert back.angle_min == scan.angle_min and back.angle_increment == scan.angle_increment
    assert (back.range_min, back.range_max, back.scan_time) == (
        scan.range_min,
        scan.range_max,
        scan.scan_time,
    )
    np.testing.assert_array_equal(back.ranges, scan.ranges)
    if intensities:
        assert back.intensities is not None and scan.intensities is not None
        np.testing.assert_array_equal(back.intensities, scan.intensities)
    else:
        assert back.intensities is None


def test_a_foreign_laser_scan_without_our_fields() -> None:
    """A scan published by someone else (plain Foxglove) still decodes, with derived fields."""
    ranges = [1.0, 2.0, float("inf"), 4.0, 5.0]
    data = fg.LaserScan(
        timestamp=fg.Timestamp(12, 500_000_000),
        frame_id="front",
        start_angle=-1.0,
        end_angle=1.0,
        ranges=ranges,
    ).encode()
    scan = codecs.decode_laser_scan(data)
    assert scan.stamp == pytest.approx(12.5)
    assert scan.angle_increment == pytest.approx(0.5)
    assert scan.angle_max == pytest.approx(1.0)
    assert scan.range_max == 5.0  # the largest finite range
    assert scan.seq == 0 and scan.frame_id == "front"


def test_pose_round_trip_over_the_whole_circle() -> None:
    for theta in np.linspace(-math.pi + 1e-9, math.pi, 17):
        pose = Pose2D(x=1.5, y=-2.25, theta=float(theta), stamp=100.125, frame_id="odom")
        back = codecs.decode_pose(codecs.encode_pose(pose))
        assert (back.x, back.y, back.frame_id) == (pose.x, pose.y, pose.frame_id)
        assert back.stamp == pytest.approx(pose.stamp, abs=1e-6)
        assert math.cos(back.theta - pose.theta) == pytest.approx(1.0, abs=1e-12)


def test_pose_yaw_from_a_general_quaternion() -> None:
    """A rotation about z given with a tilt-free quaternion of any sign still gives the yaw."""
    half = 0.6
    data = fg.PoseInFrame(
        frame_id="map",
        pose=fg.Pose(
            position=fg.Vector3(x=3.0), orientation=fg.Quaternion(z=-math.sin(half), w=-math.cos(half))
        ),
    ).encode()
    pose = codecs.decode_pose(data)
    assert pose.theta == pytest.approx(2 * half) and pose.x == 3.0 and pose.frame_id == "map"


def test_camera_frame_round_trip_encodes_the_image_once() -> None:
    img = np.zeros((48, 64, 3), np.uint8)
    img[10:30, 20:50] = (0, 200, 255)
    frame = CameraFrame(stamp=5.0, seq=42, frame_id="cam", image=img)
    back = codecs.decode_camera_frame(codecs.encode_camera_frame(frame))
    assert (back.seq, back.frame_id) == (42, "cam") and back.stamp == pytest.approx(5.0)
    assert back.jpeg is not None and back.image is None
    decoded = cv2.imdecode(np.frombuffer(back.jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert decoded is not None and decoded.shape == img.shape
    assert np.abs(decoded.astype(int) - img.astype(int)).mean() < 4  # JPEG is lossy, not wrong
    # a frame that already carries JPEG bytes is sent as is
    again = codecs.decode_camera_frame(codecs.encode_camera_frame(back))
    assert again.jpeg == back.jpeg


def test_truncated_and_mangled_messages_are_protocol_errors() -> None:
    data = codecs.encode_laser_scan(_scan(n=11))
    for cut in (1, 5, len(data) // 2, len(data) - 3):
        with pytest.raises(ProtocolError):
            codecs.decode_laser_scan(data[:cut])
    with pytest.raises(ProtocolError, match="no ranges"):
        codecs.decode_laser_scan(fg.LaserScan(frame_id="x").encode())
    with pytest.raises(ProtocolError, match="jpeg"):
        codecs.decode_camera_frame(fg.CompressedImage(data=b"\x89PNG", format="png").encode())
    with pytest.raises(ProtocolError, match="wire type"):
        codecs.decode_pose(b"\x0b\x00")  # field 1 as a group (wire type 3)


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=200))
def test_decoders_raise_only_protocol_errors(data: bytes) -> None:
    for decode in (codecs.decode_laser_scan, codecs.decode_pose, codecs.decode_camera_frame):
        with contextlib.suppress(ProtocolError):
            decode(data)


def test_frame_transform_places_the_laser_at_the_pose() -> None:
    names = _message_fields(fg.FrameTransform.get_schema().data)
    ft_no = names["foxglove.FrameTransform"]
    pose = Pose2D(2.0, 3.0, math.pi / 2, stamp=7.0, frame_id="odom")
    f = pw.fields_by_number(codecs.TRANSFORM_CODEC.encode(codecs.frame_transform(pose, "laser")))
    assert pw.last_string(f, ft_no["parent_frame_id"], "parent") == "odom"
    assert pw.last_string(f, ft_no["child_frame_id"], "child") == "laser"
    t = pw.fields_by_number(pw.last_bytes(f, ft_no["translation"], "t"))
    q = pw.fields_by_number(pw.last_bytes(f, ft_no["rotation"], "r"))
    assert (pw.last_double(t, 1, "x"), pw.last_double(t, 2, "y")) == (2.0, 3.0)
    assert pw.last_double(q, 3, "z") == pytest.approx(math.sqrt(0.5))
    assert pw.last_double(q, 4, "w") == pytest.approx(math.sqrt(0.5))


def test_codec_table() -> None:
    assert codecs.codec_for("foxglove.LaserScan").zenoh_encoding == "application/protobuf;foxglove.LaserScan"
    assert codecs.codec_for("loci.place/1").zenoh_encoding == "application/json;loci.place/1"
    with pytest.raises(ValueError, match="no codec"):
        codecs.codec_for("loci.nothing/1")
    s = codecs.mcap_schema_for("foxglove.PoseInFrame")
    assert s is not None and (s.name, s.encoding, s.message_encoding) == (
        "foxglove.PoseInFrame",
        "protobuf",
        "protobuf",
    )
    assert s.data == fg.PoseInFrame.get_schema().data
    j = codecs.mcap_schema_for("loci.graph/1")
    assert j is not None and (j.encoding, j.message_encoding) == ("jsonschema", "json")
    assert codecs.mcap_schema_for("something/else") is None


# ---- SceneUpdate -------------------------------------------------------------------------

_SCENE = _message_fields(fg.SceneUpdate.get_schema().data)


def _entities(update: fg.SceneUpdate) -> list[dict[int, list[tuple[int, int | bytes]]]]:
    entities_no = _SCENE["foxglove.SceneUpdate"]["entities"]
    top = pw.fields_by_number(update.encode())
    return [pw.fields_by_number(v) for _, v in top.get(entities_no, []) if isinstance(v, bytes)]


def test_graph_scene_has_a_sphere_per_node_and_a_line_per_edge() -> None:
    graph = {
        "nodes": [
            {"id": 0, "x": 0.0, "y": 0.0, "kind": "place", "label": "corridor"},
            {"id": 1, "x": 1.0, "y": 0.0, "kind": "doorway", "label": None},
            {"id": 2, "x": 2.0, "y": 0.5, "kind": "place", "label": "room"},
        ],
        "edges": [[0, 1], [1, 2]],
    }
    ent_fields = _SCENE["foxglove.SceneEntity"]
    (entity,) = _entities(graph_scene(graph, frame_id="odom", stamp=3.0))
    assert pw.last_string(entity, ent_fields["id"], "id") == "graph"
    assert pw.last_string(entity, ent_fields["frame_id"], "frame_id") == "odom"
    assert len(entity[ent_fields["spheres"]]) == 3
    (line,) = entity[ent_fields["lines"]]
    assert isinstance(line[1], bytes)
    points_no = _SCENE["foxglove.LinePrimitive"]["points"]
    assert len(pw.fields_by_number(line[1])[points_no]) == 4  # a line list: two points per edge
    # edges as objects (the loci.navgraph/1 document) draw the same picture
    as_objects = {**graph, "edges": [{"source": 0, "target": 1, "length": 1.0}, {"source": 1, "target": 2}]}
    assert graph_scene(as_objects, stamp=3.0).encode() == graph_scene(graph, stamp=3.0).encode()
    # classes get distinct colours, unknown is grey
    assert len({class_rgba(c) for c in ("room", "corridor", "doorway", "hallway", None)}) == 5


def test_areas_scene_labels_each_area_at_its_centroid() -> None:
    graph = {
        "nodes": [{"id": i, "x": float(i), "y": 0.0, "kind": "place", "label": "room"} for i in range(4)],
        "edges": [],
    }
    areas = {
        "areas": [{"id": 0, "label": "room", "nodes": [0, 1]}, {"id": 1, "label": None, "nodes": [2, 3]}]
    }
    (entity,) = _entities(areas_scene(areas, graph))
    texts = entity[_SCENE["foxglove.SceneEntity"]["texts"]]
    assert len(texts) == 2
    text_no = _SCENE["foxglove.TextPrimitive"]["text"]
    pose_no = _SCENE["foxglove.TextPrimitive"]["pose"]
    labels, xs = [], []
    for _, t in texts:
        assert isinstance(t, bytes)
        tf = pw.fields_by_number(t)
        labels.append(pw.last_string(tf, text_no, "text"))
        position = pw.fields_by_number(
            pw.last_bytes(pw.fields_by_number(pw.last_bytes(tf, pose_no, "pose")), 1, "p")
        )
        xs.append(pw.last_double(position, 1, "x"))
    assert labels == ["room #0", "? #1"]
    assert xs == [0.5, 2.5]
