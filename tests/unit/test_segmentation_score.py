"""Room-segmentation scores (Bormann et al. 2016) on hand-made and real ground truths."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from knowledge.labels import CORRIDOR, DOORWAY, ROOM
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.regions import extract_regions
from knowledge.topology.segmentation_score import gt_rooms, score, segment_ids, segments_from_graph


def gt_two_rooms() -> np.ndarray:
    """Room A (10 x 20 = 200 px) and room B (10 x 30 = 300 px), split by a black door line."""
    img = np.zeros((14, 56), np.uint8)
    img[2:12, 2:22] = 255  # A
    img[2:12, 23:53] = 255  # B
    img[5:9, 22] = 255  # the door opening ...
    img[5:9, 22] = 0  # ... closed by the drawn line
    return img


def test_perfect_segmentation_scores_one() -> None:
    gt = gt_two_rooms()
    pred = np.zeros(gt.shape, np.int32)
    pred[2:12, 2:22] = 7
    pred[2:12, 23:53] = 3
    s = score(pred, gt)
    assert (s["rooms"], s["segments"]) == (2, 2)
    for key in ("recall_mean", "precision_mean", "recall_pooled", "precision_pooled"):
        assert s[key] == pytest.approx(1.0)


def test_split_room_lowers_recall_by_hand() -> None:
    gt = gt_two_rooms()
    pred = np.zeros(gt.shape, np.int32)
    pred[2:12, 2:14] = 1  # 120 px of A
    pred[2:12, 14:22] = 2  # 80 px of A
    pred[2:12, 23:53] = 3
    s = score(pred, gt, min_segment_px=50)
    assert s["room_recall"] == pytest.approx([120 / 200, 1.0])
    assert s["recall_mean"] == pytest.approx((0.6 + 1.0) / 2)
    assert s["recall_pooled"] == pytest.approx((120 + 300) / 500)
    assert s["precision_mean"] == pytest.approx(1.0)
    assert s["precision_pooled"] == pytest.approx(1.0)


def test_merged_rooms_lower_precision_by_hand() -> None:
    gt = gt_two_rooms()
    pred = np.zeros(gt.shape, np.int32)
    pred[2:12, 2:22] = 5
    pred[2:12, 23:53] = 5
    s = score(pred, gt)
    assert s["segments"] == 1
    assert s["precision_mean"] == pytest.approx(300 / 500)
    assert s["precision_pooled"] == pytest.approx(300 / 500)
    assert s["recall_mean"] == pytest.approx(1.0)


def test_door_line_pixels_count_against_precision_unless_restricted() -> None:
    gt = gt_two_rooms()
    pred = np.zeros(gt.shape, np.int32)
    pred[2:12, 2:22] = 1
    pred[5:9, 22] = 1  # the segment also covers the drawn door line (4 px)
    pred[2:12, 23:53] = 2
    s = score(pred, gt)
    assert s["segment_precision"] == pytest.approx([200 / 204, 1.0])
    assert score(pred, gt, restrict_to_gt_free=True)["segment_precision"] == pytest.approx([1.0, 1.0])


def test_small_rooms_and_segments_are_ignored() -> None:
    gt = gt_two_rooms()
    gt[12:14, 30:50] = 255  # a 40 px closet (touching nothing free)
    gt[11, :] = 0  # keep it apart from B
    rooms = gt_rooms(gt)
    assert rooms.max() == 2
    pred = np.zeros(gt.shape, np.int32)
    pred[2:11, 2:22] = 1
    pred[2:11, 23:53] = 2
    pred[12:14, 30:50] = 9  # 40 px segment: ignored
    s = score(pred, gt)
    assert s["segments"] == 2
    assert s["precision_mean"] == pytest.approx(1.0)
    assert s["room_px"] == [180, 270]


def test_colour_segment_pictures_give_one_id_per_colour() -> None:
    pic = np.zeros((4, 4, 3), np.uint8)
    pic[0, 0] = (1, 2, 3)
    pic[1, 1] = (1, 2, 3)
    pic[2, 2] = (3, 2, 1)
    ids = segment_ids(pic)
    assert ids[0, 0] == ids[1, 1] == 1 + 2 * 256 + 3 * 65536
    assert ids[2, 2] != ids[0, 0] and ids[3, 3] == 0
    with pytest.raises(ValueError, match="integer"):
        segment_ids(np.zeros((3, 3), float))


def test_segments_from_graph_leave_doorways_out() -> None:
    lab = np.zeros((10, 30), np.uint8)
    lab[1:9, 1:10] = ROOM
    lab[3:6, 10:12] = DOORWAY
    lab[1:9, 12:29] = CORRIDOR
    graph = extract_regions(lab, OccupancyGrid.from_masks(lab == 0, 0.05))
    seg = segments_from_graph(graph)
    assert (seg[lab == DOORWAY] == 0).all()
    assert len(np.unique(seg[seg > 0])) == 2


def test_mismatched_sizes_are_an_error() -> None:
    with pytest.raises(ValueError, match="differ"):
        score(np.zeros((3, 3), np.int32), np.zeros((4, 4), np.uint8))


@pytest.mark.data
def test_real_ground_truth_against_itself(shared_data: Path) -> None:
    path = shared_data / "ipa" / "segmentation" / "Freiburg52_scan_gt_segmentation.png"
    gt = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert gt is not None
    rooms = gt_rooms(gt)
    assert rooms.max() >= 5
    s = score(rooms, gt)
    assert s["recall_mean"] == s["precision_mean"] == 1.0
    assert s["recall_pooled"] == s["precision_pooled"] == 1.0
    # all free pixels of the map as one segment: perfect recall for the largest room only
    grey = cv2.imread(str(path).replace("_gt_segmentation", ""), cv2.IMREAD_GRAYSCALE)
    assert grey is not None
    free = (np.asarray(grey) >= 250).astype(np.int32)
    one = score(free, gt)
    assert one["segments"] == 1
    assert one["precision_pooled"] == pytest.approx(max(one["room_px"]) / int(free.sum()))
