"""Regions, the region graph, the heuristic correction and the topological map document."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from knowledge.errors import ProtocolError
from knowledge.fileio import write_image
from knowledge.labels import CORRIDOR, DOORWAY, IPA_CODES, ROOM, read_label_image
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.regions import (
    CorrectionThresholds,
    correct_regions,
    extract_regions,
    thresholds_from_training,
)
from knowledge.topology.topomap import (
    SCHEMA,
    draw_graph,
    draw_regions,
    dumps,
    loads,
    map_background,
    overview,
    region_image,
    topomap_document,
)

RES = 0.1


def two_rooms_doorway_corridor() -> np.ndarray:
    """Room A opens to the corridor through a doorway, room B opens to it directly.

    rows 1-10 cols 1-15: A; rows 1-12 cols 17-38: B; rows 11-12 cols 5-8: doorway;
    rows 13-17 cols 1-38: corridor; everything else wall (0).
    """
    lab = np.zeros((20, 40), np.uint8)
    lab[1:11, 1:16] = ROOM
    lab[1:13, 17:39] = ROOM
    lab[11:13, 5:9] = DOORWAY
    lab[13:18, 1:39] = CORRIDOR
    return lab


def grid_for(
    lab: np.ndarray, res: float = RES, origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> OccupancyGrid:
    return OccupancyGrid.from_masks(lab == 0, res, origin=origin)


def find(graph, label: int, cell: tuple[int, int]):  # type: ignore[no-untyped-def]
    rid = int(graph.ids[cell])
    reg = graph.region(rid)
    assert reg.label == label
    return reg


def test_four_regions_with_edges_areas_and_centroids_by_hand() -> None:
    lab = two_rooms_doorway_corridor()
    graph = extract_regions(lab, grid_for(lab))
    assert len(graph.regions) == 4
    a = find(graph, ROOM, (5, 5))
    b = find(graph, ROOM, (5, 20))
    d = find(graph, DOORWAY, (11, 5))
    c = find(graph, CORRIDOR, (15, 5))
    assert (a.cells, b.cells, d.cells, c.cells) == (150, 264, 8, 190)
    assert a.area_m2 == pytest.approx(1.5)
    assert b.area_m2 == pytest.approx(2.64)
    assert d.area_m2 == pytest.approx(0.08)
    # rectangle centres; world: x = (col + 0.5) res, y = (rows - row - 0.5) res
    assert a.centroid_cell == pytest.approx((5.5, 8.0))
    assert a.centroid == pytest.approx(((8.0 + 0.5) * RES, (20 - 5.5 - 0.5) * RES))
    assert c.centroid_cell == pytest.approx((15.0, 19.5))
    assert a.bbox == (1, 1, 11, 16)
    pairs = {(e.a, e.b): e for e in graph.edges}
    assert set(pairs) == {tuple(sorted(p)) for p in ((a.id, d.id), (d.id, c.id), (b.id, c.id))}
    # doorway-room: 4 doorway cells touch A, 6 cells of A touch the doorway -> 5 cells
    assert pairs[tuple(sorted((a.id, d.id)))].border_m == pytest.approx(0.5)
    # B-corridor: 22 cells of B, 23 of the corridor (one more by the diagonal) -> 22.5 cells
    assert pairs[tuple(sorted((b.id, c.id)))].border_cells == pytest.approx(22.5)
    assert graph.neighbours(d.id).keys() == {a.id, c.id}
    np.testing.assert_array_equal(graph.labels(), lab)


def test_elongated_corridor_axes_follow_its_length() -> None:
    lab = np.zeros((30, 60), np.uint8)
    lab[5:10, 5:55] = CORRIDOR  # 5 x 50 cells, horizontal
    lab[12:28, 2:6] = CORRIDOR  # 16 x 4 cells, vertical
    graph = extract_regions(lab, grid_for(lab))
    h = find(graph, CORRIDOR, (6, 6))
    v = find(graph, CORRIDOR, (20, 3))
    # semi-axes of the ellipse with the rectangle's moments: side / sqrt(3)
    assert h.major_axis == pytest.approx((50 / math.sqrt(3) * RES, 0.0), abs=1e-9)
    assert h.minor_axis == pytest.approx((0.0, 5 / math.sqrt(3) * RES), abs=1e-9)
    assert h.elongation == pytest.approx(10.0)
    assert v.major_axis == pytest.approx((0.0, 16 / math.sqrt(3) * RES), abs=1e-9)
    assert abs(v.orientation) == pytest.approx(math.pi / 2)


def test_diagonal_corridor_orientation_in_world_frame() -> None:
    # going right along the image also goes down, i.e. towards -y in the world
    lab = np.zeros((60, 60), np.uint8)
    r, c = np.indices(lab.shape)
    lab[(np.abs(r - c) <= 2) & (r + c > 10) & (r + c < 110)] = CORRIDOR  # symmetric about the diagonal
    reg = extract_regions(lab, grid_for(lab)).regions[0]
    assert reg.orientation == pytest.approx(-math.pi / 4, abs=1e-6)
    # with the map turned by 90° in the world, the axis turns with it
    turned = extract_regions(lab, grid_for(lab, origin=(3.0, -2.0, math.pi / 2))).regions[0]
    assert turned.orientation == pytest.approx(math.pi / 4, abs=1e-6)
    assert math.hypot(*turned.major_axis) == pytest.approx(math.hypot(*reg.major_axis))


def test_tiny_false_room_in_corridor_is_merged() -> None:
    lab = np.zeros((20, 60), np.uint8)
    lab[5:15, 2:58] = CORRIDOR
    lab[8:11, 20:23] = ROOM  # 9 cells = 0.09 m²
    out, merges = correct_regions(lab, RES)
    assert (out[5:15, 2:58] == CORRIDOR).all()
    assert [(m.label_from, m.label_to, m.reason, m.cells) for m in merges] == [
        (ROOM, CORRIDOR, "small place", 9)
    ]
    # a room above the threshold stays
    lab[8:14, 20:40] = ROOM  # 1.2 m²
    out, merges = correct_regions(lab, RES)
    np.testing.assert_array_equal(out, lab)
    assert merges == []


def test_doorway_with_one_neighbour_is_merged_and_a_real_doorway_kept() -> None:
    lab = two_rooms_doorway_corridor()
    th = CorrectionThresholds(place_min_area_m2=1.0, doorway_min_area_m2=0.05)
    out, merges = correct_regions(lab, RES, th)
    np.testing.assert_array_equal(out, lab)  # the doorway joins A and the corridor: kept
    assert merges == []
    # a doorway sticking out of the corridor's end touches only the corridor
    lab2 = lab.copy()
    lab2[13:18, 36:39] = 0
    lab2[14:18, 36:39] = DOORWAY  # 0.12 m², two rows below room B
    out, merges = correct_regions(lab2, RES, th)
    assert (out[14:18, 36:39] == CORRIDOR).all()
    assert [m.reason for m in merges] == ["doorway with 1 neighbour"]
    # a doorway below the area threshold goes too, into the neighbour with the longer border
    out, merges = correct_regions(lab, RES, CorrectionThresholds(doorway_min_area_m2=0.1))
    assert [m.reason for m in merges] == ["small doorway"]
    assert (out[11:13, 5:9] != DOORWAY).all()


def test_longest_border_wins() -> None:
    lab = np.zeros((20, 40), np.uint8)
    lab[2:18, 2:20] = ROOM
    lab[2:18, 20:38] = CORRIDOR
    lab[2:5, 14:20] = DOORWAY  # 3 x 6: borders the room on 3 rows + 3 cols, the corridor on 3 rows
    lab[2:5, 14:20] = DOORWAY
    out, merges = correct_regions(lab, RES, CorrectionThresholds(doorway_min_area_m2=0.5))
    assert merges[0].label_to == ROOM
    assert (out[2:5, 14:20] == ROOM).all()


def test_corrections_repeat_until_stable() -> None:
    # corridor | doorway | small room: the room joins the doorway, which is then left with
    # one neighbour and joins the corridor
    lab = np.zeros((20, 40), np.uint8)
    lab[2:18, 2:20] = CORRIDOR
    lab[8:12, 20:24] = DOORWAY
    lab[6:14, 24:30] = ROOM  # 0.48 m²
    out, merges = correct_regions(lab, RES, CorrectionThresholds(doorway_min_area_m2=0.1))
    assert [(m.round, m.label_from, m.label_to) for m in merges] == [
        (1, ROOM, DOORWAY),
        (2, DOORWAY, CORRIDOR),
    ]
    assert set(np.unique(out)) == {0, CORRIDOR}


def test_isolated_small_region_is_kept() -> None:
    lab = np.zeros((20, 20), np.uint8)
    lab[2:5, 2:5] = ROOM
    out, merges = correct_regions(lab, RES)
    np.testing.assert_array_equal(out, lab)
    assert merges == []


def test_thresholds_from_training_ignore_speckle() -> None:
    lab = np.zeros((100, 100), np.uint8)
    lab[0:40, 0:50] = ROOM  # 20 m²
    lab[0:40, 52:62] = ROOM  # 4 m², the smallest real room
    lab[50:60, 0:100] = CORRIDOR  # 10 m²
    lab[40:50, 10:16] = DOORWAY  # 0.6 m²
    lab[40:50, 30:33] = DOORWAY  # 0.3 m²
    for k in range(20):  # one-cell speckles: 0.19 m² of places (0.6 %), 0.01 m² of doorways (1.1 %)
        lab[70 + (k % 5) * 4, 5 + (k // 5) * 4] = DOORWAY if k == 7 else (ROOM, CORRIDOR)[k % 2]
    th = thresholds_from_training([lab], RES, quantile=0.02, scale=0.5)
    assert th.place_min_area_m2 == pytest.approx(2.0)
    assert th.doorway_min_area_m2 == pytest.approx(0.15)
    assert CorrectionThresholds.from_dict(json.loads(json.dumps(th.to_dict()))) == th
    with pytest.raises(ValueError, match="unknown"):
        CorrectionThresholds.from_dict({"room_min": 1})


@pytest.mark.data
def test_thresholds_on_ipa_are_near_the_books(shared_data: Path) -> None:
    images = [
        read_label_image(p, IPA_CODES) for p in sorted((shared_data / "ipa" / "labeled").glob("*.labels.png"))
    ]
    th = thresholds_from_training(images, 0.05)
    assert 0.5 <= th.place_min_area_m2 <= 2.0  # book: 1 m²
    assert 0.05 <= th.doorway_min_area_m2 <= 0.2  # book: 0.1 m²


# ---------------------------------------------------------------------- document and pictures
def test_document_round_trip_and_content() -> None:
    lab = two_rooms_doorway_corridor()
    lab2 = lab.copy()
    lab2[15:17, 30:32] = ROOM  # a tiny false room, corrected away
    grid = grid_for(lab)
    th = CorrectionThresholds()
    corrected, merges = correct_regions(lab2, RES, CorrectionThresholds(doorway_min_area_m2=0.05))
    graph = extract_regions(corrected, grid)
    doc = topomap_document(graph, grid, thresholds=th, merges=merges, meta={"iterations": 50})
    text = dumps(doc)
    back = loads(text)
    assert back == json.loads(json.dumps(doc))
    assert back["schema"] == SCHEMA
    assert len(back["nodes"]) == 4 and len(back["edges"]) == 3
    door = next(n for n in back["nodes"] if n["label"] == "doorway")
    assert door["degree"] == 2
    assert door["area_m2"] == pytest.approx(0.08)
    assert back["corrections"][0]["from"] == "room" and back["corrections"][0]["to"] == "corridor"
    assert back["thresholds"]["place_min_area_m2"] == 1.0
    # node ids are the pixel values of the region image
    ids = region_image(graph)
    assert ids.dtype == np.uint16
    for n in back["nodes"]:
        r, c = (round(v) for v in n["centroid_cell"])
        assert n["id"] in set(
            np.unique(ids[n["bbox_cells"][0] : n["bbox_cells"][2], n["bbox_cells"][1] : n["bbox_cells"][3]])
        )
        assert 0 <= r < lab.shape[0] and 0 <= c < lab.shape[1]


@pytest.mark.parametrize(
    "breakage",
    [
        lambda d: d.update(schema="loci.topomap/0"),
        lambda d: d.pop("nodes"),
        lambda d: d["edges"].append({"source": 1, "target": 99, "border_m": 1, "border_cells": 1}),
        lambda d: d["nodes"][0].pop("centroid"),
    ],
)
def test_bad_documents_are_refused(breakage) -> None:  # type: ignore[no-untyped-def]
    lab = two_rooms_doorway_corridor()
    doc = json.loads(json.dumps(topomap_document(extract_regions(lab, grid_for(lab)), grid_for(lab))))
    breakage(doc)
    with pytest.raises(ProtocolError):
        loads(json.dumps(doc))


def test_pictures(tmp_path: Path) -> None:
    lab = two_rooms_doorway_corridor()
    grid = grid_for(lab)
    graph = extract_regions(lab, grid)
    bg = map_background(grid)
    regions = draw_regions(graph, bg)
    assert regions.shape == (*lab.shape, 3) and regions.dtype == np.uint8
    # four distinct region colours, none of them the colour of non-region cells
    colours = {tuple(regions[cell]) for cell in ((5, 5), (5, 20), (11, 5), (15, 5))}
    assert len(colours) == 4
    assert tuple(regions[0, 0]) not in colours
    pic = draw_graph(graph, bg)
    assert pic.shape == (*lab.shape, 3)
    # a node disc is drawn at the corridor's centroid in the corridor's class colour
    from knowledge.labels import CLASS_COLORS_BGR

    assert tuple(int(v) for v in pic[15, 19]) == CLASS_COLORS_BGR[CORRIDOR]
    big = overview([("labels", bg), ("regions", regions), ("graph", pic)])
    assert big.ndim == 3 and big.shape[1] >= 2 * lab.shape[1]
    write_image(tmp_path / "overview.png", big)
    assert (tmp_path / "overview.png").stat().st_size > 0
