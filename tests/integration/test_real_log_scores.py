"""Scoring a replay against a log's truth, on small worlds drawn here.

The labelled map: a corridor along the bottom, two rooms above it, each with a door to the
corridor, and a connecting door between the rooms; 0.05 m per pixel, aligned to the log's
frame by a known similarity transform. A scripted path goes corridor → room A → room B →
corridor, so the doors driven through, the rooms visited and the crossings are known.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.cli import loci

from agent.bus.bridge import RawSample
from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC
from agent.recording.recorder import McapSink
from drivers.messages import LaserScan, Pose2D
from knowledge.evaluation.real_logs import Alignment, LabelMap, Truth, evaluate, label_names, match_stamps
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast

ROOM, CORRIDOR, DOORWAY = 77, 115, 179
ALIGN = Alignment(rot_deg=10.0, m_per_px=0.05, tx_px=20.0, ty_px=140.0, mirror=1)


def label_image() -> np.ndarray:
    """200 × 150 px (10 m × 7.5 m): corridor rows 100-139, rooms A (cols 0-99) and B (100-199)
    rows 0-89, walls between; doors: A ↔ corridor at cols 40-59, B ↔ corridor at 140-159, A ↔ B
    at rows 40-59 (door regions drawn across the wall, 0.5 m either side)."""
    img = np.zeros((150, 200), dtype=np.uint8)
    img[100:140, :] = CORRIDOR
    img[0:90, 0:98] = ROOM
    img[0:90, 102:200] = ROOM
    img[80:110, 40:60] = DOORWAY
    img[80:110, 140:160] = DOORWAY
    img[40:60, 90:110] = DOORWAY
    return img


def px_to_m(points_px: list[tuple[float, float]]) -> np.ndarray:
    return ALIGN.to_m(np.array(points_px, dtype=np.float64))


def path_px() -> np.ndarray:
    """(column, row) waypoints: corridor → room A → room B → corridor, sampled every 4 px."""
    way = [(10, 120), (50, 120), (50, 60), (50, 50), (150, 50), (150, 60), (150, 120), (190, 120)]
    pts = []
    for (a, b), (c, d) in itertools.pairwise(way):
        n = max(1, int(math.hypot(c - a, d - b) / 4))
        pts += [(a + (c - a) * k / n, b + (d - b) * k / n) for k in range(n)]
    return np.array(pts)


def truth_and_path() -> tuple[Truth, np.ndarray, np.ndarray]:
    lm = LabelMap.from_image(label_image(), ALIGN)
    xy = ALIGN.to_m(path_px())
    heading = np.r_[np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0])), 0.0]
    stamps = 100.0 + 0.2 * np.arange(len(xy))
    return Truth.from_map(lm, stamps, np.column_stack([xy, heading])), stamps, xy


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-180, 180),
    st.floats(0.01, 0.2),
    st.floats(-500, 500),
    st.floats(-500, 500),
    st.sampled_from([1, -1]),
    st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=1, max_size=10),
)
def test_the_alignment_maps_metres_to_pixels_and_back(
    rot: float, s: float, tx: float, ty: float, mirror: int, pts: list[tuple[float, float]]
) -> None:
    a = Alignment(rot, s, tx, ty, mirror)
    xy = np.array(pts)
    assert np.allclose(a.to_m(a.to_px(xy)), xy, atol=1e-6)
    # a similarity: distances scale by 1 / m_per_px
    if len(pts) >= 2:
        d_m = np.hypot(*(xy[0] - xy[1]))
        d_px = np.hypot(*(a.to_px(xy)[0] - a.to_px(xy)[1]))
        assert d_px == pytest.approx(d_m / s, rel=1e-6, abs=1e-6)


def test_the_data_files_transform_as_their_readme_says() -> None:
    """README: y' = mirror·y; X = (cos θ·x − sin θ·y')/s; Y = (sin θ·x + cos θ·y')/s; col = X + tx; row = −Y + ty."""
    doc = {"rot_deg": 90.0, "m_per_px": 0.5, "tx_px": 10.0, "ty_px": 20.0, "mirror": -1}
    a = Alignment.from_json(json.dumps(doc))
    # (1, 2): y' = -2; X = (0·1 − 1·(−2))/0.5 = 4; Y = (1·1 + 0)/0.5 = 2 → col 14, row 18
    assert a.to_px(np.array([[1.0, 2.0]])) == pytest.approx(np.array([[14.0, 18.0]]))
    with pytest.raises(ValueError, match="rot_deg"):
        Alignment.from_json({"m_per_px": 1})


def test_labels_regions_and_doors_of_a_drawn_map() -> None:
    lm = LabelMap.from_image(label_image(), ALIGN)
    assert sorted(lm.region_class.values()) == ["corridor", "room", "room"]
    assert int(lm.doors.max()) == 3
    # a point on the wall between the rooms takes the nearest room; far outside: nothing
    cls, reg = lm.place_at(px_to_m([(99, 20), (50, 60), (50, 120), (500, 500)]))
    assert list(cls) == ["room", "room", "corridor", ""] and reg[3] == 0
    assert list(lm.class_at(px_to_m([(50, 95)]))) == ["doorway"]
    centres = lm.door_centres()
    assert len(centres) == 3
    assert min(math.dist(c, tuple(px_to_m([(49.5, 94.5)])[0])) for c in centres.values()) < 1e-6


def test_doors_driven_through_are_where_the_path_changes_place() -> None:
    truth, _, _ = truth_and_path()
    driven = [d for d in truth.doors if d.driven]
    # corridor → A, A → B (room to room), B → corridor
    assert len(driven) == 3 and sum(d.room_to_room for d in driven) == 1
    for d, at in zip(
        sorted(driven, key=lambda d: d.center[0]),
        sorted(px_to_m([(50, 95), (95, 50), (150, 95)]).tolist()),
        strict=True,
    ):
        assert math.dist(d.center, at) < 0.3
    assert not any(d.driven for d in truth.doors if d not in driven)


def test_a_short_stay_across_a_drawn_wall_is_not_a_door() -> None:
    """A path along the wall between the rooms, drawn a little off, dips into room B for 0.2 m."""
    lm = LabelMap.from_image(label_image(), ALIGN)
    cols = np.r_[np.linspace(60, 96, 10), [101, 101], np.linspace(96, 60, 10)]
    xy = ALIGN.to_m(np.column_stack([cols, np.full(cols.size, 20.0)]))
    truth = Truth.from_map(lm, 0.2 * np.arange(cols.size), np.column_stack([xy, np.zeros(cols.size)]))
    assert not any(d.driven for d in truth.doors)


def test_scores_of_a_replay() -> None:
    truth, stamps, xy = truth_and_path()
    labels = truth.labels.copy()
    # the prediction: right, except that three room scans say corridor and doorway scans say room
    pred = np.where(labels == "doorway", "room", labels).astype(object)
    wrong = np.flatnonzero(labels == "room")[:3]
    pred[wrong] = "corridor"
    lm = truth.label_map
    assert lm is not None
    nodes = [
        {"id": 1, "x": float(xy[2, 0]), "y": float(xy[2, 1]), "kind": "place", "label": "corridor"},
        {"id": 2, "x": float(xy[28, 0]), "y": float(xy[28, 1]), "kind": "place", "label": "room"},
        {"id": 3, "x": float(xy[45, 0]), "y": float(xy[45, 1]), "kind": "place", "label": "room"},
        {"id": 4, "x": float(xy[-2, 0]), "y": float(xy[-2, 1]), "kind": "place", "label": "room"},
    ]
    a_door = px_to_m([(50, 96)])[0]
    nodes += [
        {"id": 5, "x": float(a_door[0]), "y": float(a_door[1]), "kind": "doorway", "label": "doorway"},
        {"id": 6, "x": float(xy[30, 0]), "y": float(xy[30, 1]), "kind": "doorway", "label": "doorway"},
    ]
    graph = {"nodes": nodes, "edges": []}
    areas = {"areas": [{"id": 1, "nodes": [1, 4]}, {"id": 2, "nodes": [2, 3]}]}
    s = evaluate(truth, stamps + 0.001, pred, graph, areas, stamp_tolerance=0.01)
    n_two = int(np.isin(labels, ["room", "corridor"]).sum())
    assert s.scans_scored == len(stamps) and s.two_class.n == n_two
    assert s.two_class.accuracy == pytest.approx((n_two - 3) / n_two)
    assert s.three_class.recall[2] == 0.0  # no doorway scan was called doorway
    # nodes: the last node stands in the corridor but says room
    assert (s.nodes.n, s.nodes.accuracy) == (4, 0.75)
    d = s.doors
    assert (d["doors_driven_through"], d["doors_found"], d["room_to_room_crossings"]) == (2, 1, 1)
    assert d["false_doorway_nodes"] == 1 and d["false"] == [6]
    a = s.areas
    assert (a["rooms_visited"], a["rooms_with_own_area"]) == (2, 0)  # rooms A and B share area 2
    json.dumps(s.as_dict())
    with pytest.raises(ValueError, match="same clock"):
        evaluate(truth, stamps + 1000.0, pred, graph, areas)


def test_per_scan_labels_without_a_map_give_doors_from_the_label_runs() -> None:
    codes = np.array([115] * 10 + [179] * 3 + [77] * 10 + [179] * 3 + [115] * 5 + [179] * 2 + [115] * 5)
    xy = np.column_stack([0.1 * np.arange(codes.size), np.zeros(codes.size)])
    truth = Truth.from_arrays(
        np.arange(codes.size, dtype=float), np.column_stack([xy, np.zeros(codes.size)]), codes
    )
    assert list(label_names(np.array([77, 115, 179, 0]))) == ["room", "corridor", "doorway", ""]
    assert [d.driven for d in truth.doors] == [True, True, False]
    # a node's class: the majority of the labelled scans near it
    classes, _ = truth.place_of(np.array([[0.5, 0.0], [1.7, 0.0], [9.0, 9.0]]))
    assert list(classes) == ["corridor", "room", ""]


def test_matching_stamps() -> None:
    t = np.array([1.0, 2.0, 3.0])
    assert list(match_stamps(t, np.array([0.995, 2.004, 2.5, 3.01, 9.0]), 0.01)) == [0, 1, -1, 2, -1]


@pytest.mark.slow
def test_loci_evaluate_log_replays_and_scores_a_recording(tmp_path: Path) -> None:
    """The drawn world as a real log: a front laser ray cast in it along the path, odometry
    at the scan stamps, per-scan labels in the data set's format beside the labelled map."""
    align = Alignment(rot_deg=0.0, m_per_px=0.05, tx_px=20.0, ty_px=140.0)
    img = label_image()
    # the map frame of the grid is the log frame (rot 0, scale = resolution): origin from tx, ty
    grid = OccupancyGrid.from_masks(img == 0, 0.05, origin=(-20 * 0.05, -(150 - 140) * 0.05, 0.0))
    xy = align.to_m(path_px())
    heading = np.r_[np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0])), 0.0]
    heading[-1] = heading[-2]
    poses = np.column_stack([xy, heading])
    stamps = 1.7e9 + 0.2 * np.arange(len(xy))
    ranges = cast(grid, poses, n_beams=361, fov=math.pi, max_range=30.0)
    rec = tmp_path / "drawn.mcap"
    with McapSink(rec) as sink:
        for i, (t, p, r) in enumerate(zip(stamps, poses, ranges, strict=True)):
            ns = int(t * 1e9)
            pose = Pose2D(*p, stamp=float(t))
            scan = LaserScan(float(t), i, "laser", -math.pi / 2, math.pi / 360, 30.0, r)
            sink.write(RawSample("loci/drawn/odom", POSE_CODEC.encode(pose), POSE_CODEC.zenoh_encoding, ns))
            sink.write(
                RawSample(
                    "loci/drawn/scan", LASER_SCAN_CODEC.encode(scan), LASER_SCAN_CODEC.zenoh_encoding, ns + 1
                )
            )
    lm = LabelMap.from_image(img, align)
    truth = Truth.from_map(lm, stamps, poses)
    codes = {"room": 77, "corridor": 115, "doorway": 179}
    np.savez(
        tmp_path / "labels.npz",
        t=stamps,
        pose=poses,
        label=np.array([codes[c] for c in truth.labels], dtype=np.int16),
        map_px=np.rint(align.to_px(xy)).astype(np.int64),
        align=np.array(
            json.dumps({"rot_deg": 0.0, "m_per_px": 0.05, "tx_px": 20.0, "ty_px": 140.0, "mirror": 1})
        ),
    )
    cv2.imwrite(str(tmp_path / "map.png"), img)
    out = loci(
        "evaluate",
        "log",
        str(rec),
        "--labels",
        str(tmp_path / "labels.npz"),
        "--label-map",
        str(tmp_path / "map.png"),
        "--out-dir",
        str(tmp_path / "out"),
        "--json",
    )
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["replay"]["balanced"] and got["scans"]["scored"] == len(stamps)
    assert 0.0 <= got["scans"]["room_corridor"]["accuracy"] <= 1.0
    assert got["doorways"]["doors_driven_through"] == 2 and got["areas"]["rooms_visited"] == 2
    assert json.loads((tmp_path / "out" / "scores.json").read_text()) == got
    assert cv2.imread(str(tmp_path / "out" / "evaluation.png")) is not None
    # the same truth from the map and the alignment alone
    (tmp_path / "align.json").write_text(
        json.dumps({"rot_deg": 0, "m_per_px": 0.05, "tx_px": 20, "ty_px": 140})
    )
    text = loci(
        "evaluate",
        "log",
        str(rec),
        "--labels",
        str(tmp_path / "map.png"),
        "--align",
        str(tmp_path / "align.json"),
    )
    assert text.returncode == 0, text.stderr
    assert "per scan, room/corridor:" in text.stdout and "doors driven through" in text.stdout
    bad = loci("evaluate", "log", str(rec), "--labels", str(tmp_path / "map.png"))
    assert bad.returncode == 2 and "--align" in bad.stderr
