"""Room-segmentation scores against a hand-made ground truth (Bormann et al., ICRA 2016).

Ground truth: a ``*_gt_segmentation.png`` map in which every doorway is closed by a drawn
black line. Pixels with grey value ``>= free_threshold`` (250) are free; each 8-connected free
region is one room; rooms of ``min_room_px`` (100) pixels or fewer are ignored.

Prediction: an integer image of segment ids (0 = no segment), e.g. the regions labelled room,
corridor or hallway (:func:`segments_from_graph`). Segments of ``min_segment_px`` (100) pixels
or fewer are ignored too, and segments are **not** clipped to the ground truth's free space
(the drawn door lines count against precision): both as in the reference evaluation of
ipa_room_segmentation, so that the numbers compare with the published ones.
``restrict_to_gt_free=True`` clips the segments to the ground truth's free pixels first.

Scores:

* recall of a room = (largest overlap of the room with any segment) / room size;
* precision of a segment = (largest overlap of the segment with any room) / segment size;
* ``*_mean``: the average over rooms (segments); ``*_pooled``: the summed best overlaps over
  the summed sizes (pixel-pooled).

The reference thresholds the ground truth at ``> 250``; the data README says ``>= 250``, which is
our default (a few hundred pixels of value 250 in some maps; pass ``free_threshold=251`` for
the reference's rule).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from knowledge.labels import CORRIDOR, HALLWAY, ROOM
from knowledge.places.regions import RegionGraph


def gt_rooms(gt_image: np.ndarray, *, free_threshold: int = 250, min_room_px: int = 100) -> np.ndarray:
    """``(rows, cols)`` int32 room ids of a ground-truth segmentation image (0 = not a room).

    ``gt_image`` is grey ``(rows, cols)`` or BGR/BGRA ``(rows, cols, 3|4)`` uint8. Rooms of at
    most ``min_room_px`` pixels get id 0; the others are numbered 1..n.
    """
    grey = _grey(gt_image)
    rooms, n = ndimage.label(grey >= free_threshold, structure=np.ones((3, 3), bool))
    if n == 0:
        return rooms.astype(np.int32)
    size = np.bincount(rooms.ravel(), minlength=n + 1)
    keep = size > min_room_px
    keep[0] = False
    lut = np.zeros(n + 1, dtype=np.int32)
    lut[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    return lut[rooms]


def segment_ids(image: np.ndarray) -> np.ndarray:
    """Segment ids from a picture: a 2-D integer image as it is; a BGR(A) image as one id per
    colour (``b + 256 g + 65536 r``), black = 0."""
    img = np.asarray(image)
    if img.ndim == 2:
        if not np.issubdtype(img.dtype, np.integer):
            raise ValueError(f"a segment image must hold integer ids, got dtype {img.dtype}")
        return img.astype(np.int64)
    if img.ndim == 3 and img.shape[2] in (3, 4) and img.dtype == np.uint8:
        c = img[..., :3].astype(np.int64)
        return c[..., 0] + (c[..., 1] << 8) + (c[..., 2] << 16)
    raise ValueError(
        f"a segment image must be 2-D ids or an 8-bit BGR(A) picture, got {img.shape} {img.dtype}"
    )


def segments_from_graph(graph: RegionGraph, codes: Iterable[int] = (ROOM, CORRIDOR, HALLWAY)) -> np.ndarray:
    """``(rows, cols)`` int32: the ids of the regions whose label is in ``codes``, 0 elsewhere."""
    wanted = set(int(c) for c in codes)
    lut = np.zeros(len(graph.regions) + 1, dtype=np.int32)
    for reg in graph.regions:
        if reg.label in wanted:
            lut[reg.id] = reg.id
    return lut[graph.ids]


def score(
    pred_segments: np.ndarray,
    gt_image: np.ndarray,
    *,
    free_threshold: int = 250,
    min_room_px: int = 100,
    min_segment_px: int = 100,
    restrict_to_gt_free: bool = False,
) -> dict[str, Any]:
    """Recall and precision of a predicted segmentation (see the module docstring).

    Args:
        pred_segments: ``(rows, cols)`` integer segment ids (0 = none), or a colour picture
            (:func:`segment_ids`).
        gt_image: the ground-truth segmentation picture, same size.

    Returns:
        A JSON-friendly dict: ``recall_mean``, ``precision_mean``, ``recall_pooled``,
        ``precision_pooled`` (floats in [0, 1]; 0 when there is nothing to score), ``rooms`` and
        ``segments`` (counts scored), ``room_recall`` and ``segment_precision`` (lists, in room
        id / ascending segment id order), and ``room_px`` and ``segment_px`` (sizes).
    """
    seg = segment_ids(pred_segments)
    rooms = gt_rooms(gt_image, free_threshold=free_threshold, min_room_px=min_room_px)
    if seg.shape != rooms.shape:
        raise ValueError(f"segments {seg.shape} and ground truth {rooms.shape} differ in size")
    if restrict_to_gt_free:
        seg = np.where(_grey(gt_image) >= free_threshold, seg, 0)
    n_rooms = int(rooms.max())
    # compact segment ids 1..m, dropping small segments
    flat = seg.ravel()
    nz = flat != 0
    uniq, inv = np.unique(flat[nz], return_inverse=True)
    seg_size_all = np.bincount(inv, minlength=uniq.size)
    keep = seg_size_all > min_segment_px
    remap = np.zeros(uniq.size, dtype=np.int64)
    remap[keep] = np.arange(1, int(keep.sum()) + 1)
    seg_c = np.zeros(flat.size, dtype=np.int64)
    seg_c[nz] = remap[inv]
    m = int(keep.sum())
    room_px = np.bincount(rooms.ravel(), minlength=n_rooms + 1)[1:]
    seg_px = seg_size_all[keep]
    r_flat = rooms.ravel().astype(np.int64)
    both = (seg_c > 0) & (r_flat > 0)
    pair, overlap = np.unique(seg_c[both] * (n_rooms + 1) + r_flat[both], return_counts=True)
    s_of, r_of = np.divmod(pair, n_rooms + 1)
    best_for_room = np.zeros(n_rooms + 1, dtype=np.int64)
    best_for_seg = np.zeros(m + 1, dtype=np.int64)
    np.maximum.at(best_for_room, r_of, overlap)
    np.maximum.at(best_for_seg, s_of, overlap)
    room_recall = best_for_room[1:] / np.maximum(room_px, 1)
    seg_precision = best_for_seg[1:] / np.maximum(seg_px, 1)

    def ratio(num: float, den: float) -> float:
        return float(num / den) if den > 0 else 0.0

    return {
        "recall_mean": float(room_recall.mean()) if n_rooms else 0.0,
        "precision_mean": float(seg_precision.mean()) if m else 0.0,
        "recall_pooled": ratio(best_for_room[1:].sum(), room_px.sum()),
        "precision_pooled": ratio(best_for_seg[1:].sum(), seg_px.sum()),
        "rooms": n_rooms,
        "segments": m,
        "room_recall": [round(float(v), 6) for v in room_recall],
        "segment_precision": [round(float(v), 6) for v in seg_precision],
        "room_px": [int(v) for v in room_px],
        "segment_px": [int(v) for v in seg_px],
    }


def _grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError(f"a ground-truth segmentation must be an 8-bit image, got {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"a ground-truth segmentation must be grey or BGR(A), got shape {img.shape}")
