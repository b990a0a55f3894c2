"""Scores of a replay of a real robot log against its ground truth.

The truth comes in one of two forms (``loci evaluate log``, docs/real_logs.md):

* **Per-scan labels** (:meth:`Truth.from_npz`, the ``fr079_labels_provisional.npz`` format):
  arrays ``t`` (the scan's stamp, seconds), ``pose`` (``(n, 3)`` x, y, theta in the log's
  frame), ``label`` (the class of the place where the robot stands, in IPA grey values
  77 room, 115 corridor, 179 doorway, or our codes 1 room, 2 corridor, 3 doorway, 4
  hallway), and optionally ``map_px`` (``(n, 2)`` column, row of the robot in a labelled
  map) and ``align`` (the JSON of an :class:`Alignment`).
* **A labelled map and an alignment** (:meth:`Truth.from_map`): each scan's label is the map's
  class at the scan's pose, which must then be in the frame the alignment was fitted in (a
  SLAM-corrected log).

With a labelled map (:class:`LabelMap`; given alone, or beside per-scan labels), each place
is also a *region*: a connected component of room pixels (one room) or of corridor pixels,
and each door is a connected component of doorway pixels. Without one, doors are the runs
of doorway-labelled scans along the path, and regions are unknown.

What is scored (:func:`evaluate`):

A replay of part of a log is scored against the labelled scans of its stretch (between its
first and last processed stamp): the doors, rooms and nodes of that stretch.

* **per scan**: room/corridor accuracy over the scans whose truth is room or corridor
  (hallway counts as corridor; a doorway prediction there is wrong) and 3-class accuracy
  (room, corridor, doorway), each with balanced accuracy and the confusion matrix, and the
  accuracy of always answering the most frequent class, for scale;
* **per navigation node**: a place node's label against the class of the place it stands in
  (the map's class there, else the majority truth of the scans within ``node_radius``);
* **doorways**: each door the robot *drove through* (the place before it differs from the
  place after it) has a doorway node within ``door_radius`` (recall); each doorway node has a
  labelled door within ``door_radius`` (precision);
* **areas against the places visited** (needs regions): for each region the robot's nodes
  stand in, the area holding most of them; a room is *its own area* when that area holds at
  least half of the room's nodes and nothing else beyond ``area_purity``; and the segmentation
  scores of Bormann et al. over nodes (recall per region, precision per area; their means and
  the node-pooled ratios).

Everything is in metres in the log's frame; no file is read here except by the two
``from_*`` constructors' callers passing arrays (pure code).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from knowledge.labels import CLASS_NAMES, CORRIDOR, DOORWAY, HALLWAY, IPA_CODES, ROOM
from knowledge.learning.metrics import Scores, score

__all__ = [
    "Alignment",
    "Door",
    "LabelMap",
    "LogScores",
    "Truth",
    "evaluate",
    "label_names",
    "match_stamps",
]

#: The classes of the two per-scan scores.
TWO_CLASSES = ("room", "corridor")
THREE_CLASSES = ("room", "corridor", "doorway")


def label_names(codes: np.ndarray) -> np.ndarray:
    """Label codes (IPA grey values or our codes) → class names (``""`` for no label)."""
    c = np.asarray(codes).astype(np.int64)
    ipa = set(np.unique(c).tolist()) - {0} <= set(IPA_CODES)
    table = {**{g: CLASS_NAMES[k] for g, k in IPA_CODES.items()}} if ipa else dict(CLASS_NAMES)
    return np.array([table.get(int(v), "") for v in c], dtype=object)


def _as_two(labels: np.ndarray) -> np.ndarray:
    """Hallway counted as corridor (the book's room/corridor distinction)."""
    out = np.asarray(labels, dtype=object).copy()
    out[out == "hallway"] = "corridor"
    return out


@dataclass(frozen=True)
class Alignment:
    """A similarity transform from log metres to label-map pixels (with an optional mirror).

    ``y' = mirror·y``; ``X = (cos θ·x − sin θ·y') / s``; ``Y = (sin θ·x + cos θ·y') / s``;
    column = ``X + tx``; row = ``−Y + ty``, with θ = ``rot_deg``, s = ``m_per_px``.
    """

    rot_deg: float
    m_per_px: float
    tx_px: float
    ty_px: float
    mirror: int = 1

    def __post_init__(self) -> None:
        if not (math.isfinite(self.m_per_px) and self.m_per_px > 0):
            raise ValueError(f"m_per_px must be a positive number of metres, got {self.m_per_px!r}")
        if self.mirror not in (1, -1):
            raise ValueError(f"mirror must be 1 or -1, got {self.mirror!r}")

    @classmethod
    def from_json(cls, doc: Mapping[str, Any] | str) -> Alignment:
        d = json.loads(doc) if isinstance(doc, str) else doc
        try:
            return cls(
                float(d["rot_deg"]),
                float(d["m_per_px"]),
                float(d["tx_px"]),
                float(d["ty_px"]),
                int(d.get("mirror", 1)),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(
                f"an alignment needs rot_deg, m_per_px, tx_px, ty_px (and optionally mirror): {exc}"
            ) from exc

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """``(k, 2)`` metres → ``(k, 2)`` float (column, row)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        th = math.radians(self.rot_deg)
        c, s = math.cos(th), math.sin(th)
        x, y = p[:, 0], self.mirror * p[:, 1]
        X = (c * x - s * y) / self.m_per_px
        Y = (s * x + c * y) / self.m_per_px
        return np.column_stack((X + self.tx_px, -Y + self.ty_px))

    def to_m(self, px: np.ndarray) -> np.ndarray:
        """``(k, 2)`` (column, row) → ``(k, 2)`` metres (the inverse of :meth:`to_px`)."""
        q = np.asarray(px, dtype=np.float64).reshape(-1, 2)
        X = (q[:, 0] - self.tx_px) * self.m_per_px
        Y = -(q[:, 1] - self.ty_px) * self.m_per_px
        th = math.radians(self.rot_deg)
        c, s = math.cos(th), math.sin(th)
        x = c * X + s * Y
        y = -s * X + c * Y
        return np.column_stack((x, self.mirror * y))


@dataclass(frozen=True, eq=False)
class LabelMap:
    """A labelled map with its regions and doors (see the module docstring).

    Attributes:
        codes: ``(rows, cols)`` uint8 class codes (1 room, 2 corridor, 3 doorway, 4 hallway).
        alignment: log metres → these pixels.
        regions: ``(rows, cols)`` int32: a region id per room/corridor/hallway pixel (0: none);
            8-connected components of one class.
        region_class: region id → class name.
        doors: ``(rows, cols)`` int32 door ids (8-connected doorway components; 0: none).
    """

    codes: np.ndarray
    alignment: Alignment
    regions: np.ndarray = field(init=False)
    region_class: dict[int, str] = field(init=False)
    doors: np.ndarray = field(init=False)

    #: Components of fewer pixels are specks of paint, not places or doors.
    MIN_REGION_PX = 20

    def __post_init__(self) -> None:
        codes = np.asarray(self.codes)
        if codes.ndim != 2:
            raise ValueError(f"a label map must be 2-D, got shape {codes.shape}")
        eight = np.ones((3, 3), dtype=bool)
        regions = np.zeros(codes.shape, dtype=np.int32)
        region_class: dict[int, str] = {}
        for code in (ROOM, CORRIDOR, HALLWAY):
            comp, n = ndimage.label(codes == code, structure=eight)
            sizes = np.bincount(comp.ravel(), minlength=n + 1)
            for k in range(1, n + 1):
                if sizes[k] >= self.MIN_REGION_PX:
                    rid = len(region_class) + 1
                    regions[comp == k] = rid
                    region_class[rid] = CLASS_NAMES[code]
        doors, n = ndimage.label(codes == DOORWAY, structure=eight)
        sizes = np.bincount(doors.ravel(), minlength=n + 1)
        lut = np.zeros(n + 1, dtype=np.int32)
        keep = np.flatnonzero(sizes >= self.MIN_REGION_PX)
        keep = keep[keep > 0]
        lut[keep] = np.arange(1, keep.size + 1, dtype=np.int32)
        object.__setattr__(self, "codes", codes.astype(np.uint8))
        object.__setattr__(self, "regions", regions)
        object.__setattr__(self, "region_class", region_class)
        object.__setattr__(self, "doors", lut[doors])

    @classmethod
    def from_image(cls, image: np.ndarray, alignment: Alignment) -> LabelMap:
        """From a label image in IPA grey values (77/115/179) or in our codes (1–4)."""
        img = np.asarray(image)
        values = set(np.unique(img).tolist()) - {0}
        if values <= set(IPA_CODES):
            lut = np.zeros(256, dtype=np.uint8)
            for grey, code in IPA_CODES.items():
                lut[grey] = code
            img = lut[img]
        elif not values <= set(CLASS_NAMES):
            raise ValueError(
                f"a label map holds IPA grey values (77, 115, 179) or codes 1-4, got {sorted(values)[:8]}"
            )
        return cls(img, alignment)

    def _pixels(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        px = np.rint(self.alignment.to_px(xy)).astype(np.int64)
        rows, cols = self.codes.shape
        inside = (px[:, 0] >= 0) & (px[:, 0] < cols) & (px[:, 1] >= 0) & (px[:, 1] < rows)
        return px[:, 1].clip(0, rows - 1), px[:, 0].clip(0, cols - 1), inside

    def place_at(self, xy: np.ndarray, reach: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
        """``(classes (k,) object, regions (k,) int)`` of the places at points in metres.

        A point on a wall, a door or furniture takes the nearest room/corridor pixel within
        ``reach`` metres (positions drift from idealised drawn walls); farther: ``""``, 0.
        """
        r, c, inside = self._pixels(xy)
        # distance to, and index of, the nearest region pixel, computed once per map
        dist, (ir, ic) = self._nearest
        rr, cc = ir[r, c], ic[r, c]
        ok = inside & (dist[r, c] * self.alignment.m_per_px <= reach)
        reg = np.where(ok, self.regions[rr, cc], 0)
        cls = np.array([self.region_class.get(int(k), "") for k in reg], dtype=object)
        return cls, reg

    def class_at(self, xy: np.ndarray) -> np.ndarray:
        """``(k,)`` class names of the pixels at points in metres (doorway included; ``""``: none)."""
        r, c, inside = self._pixels(xy)
        codes = np.where(inside, self.codes[r, c], 0)
        return np.array([CLASS_NAMES.get(int(k), "") for k in codes], dtype=object)

    def door_at(self, xy: np.ndarray) -> np.ndarray:
        """``(k,)`` door ids at points in metres (0: not in a door)."""
        r, c, inside = self._pixels(xy)
        return np.where(inside, self.doors[r, c], 0)

    def door_centres(self) -> dict[int, tuple[float, float]]:
        """Door id → its centre in metres (the centroid of its pixels)."""
        ids = np.arange(1, int(self.doors.max()) + 1)
        if ids.size == 0:
            return {}
        centres = ndimage.center_of_mass(np.ones_like(self.doors), self.doors, ids)
        px = np.array([[c, r] for r, c in centres], dtype=np.float64)
        xy = self.alignment.to_m(px)
        return {int(i): (float(x), float(y)) for i, (x, y) in zip(ids, xy, strict=True)}

    @property
    def _nearest(self) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        cached = self.__dict__.get("_nearest_cache")
        if cached is None:
            dist, idx = ndimage.distance_transform_edt(self.regions == 0, return_indices=True)
            cached = (dist, (idx[0], idx[1]))
            object.__setattr__(self, "_nearest_cache", cached)
        return cached


@dataclass(frozen=True)
class Door:
    """A labelled door: its centre (metres, log frame), whether the robot drove through it,
    how often it did, and whether it joins two rooms (in a drawn map, a path along a wall
    drawn a little off also crosses from room to room: such crossings are reported apart)."""

    id: int
    center: tuple[float, float]
    driven: bool
    passages: int = 0
    room_to_room: bool = False


@dataclass(frozen=True, eq=False)
class Truth:
    """The ground truth of a log (see the module docstring).

    Attributes:
        stamps: ``(n,)`` scan stamps, seconds.
        poses: ``(n, 3)`` the robot's (laser's) x, y, theta in the log's frame.
        labels: ``(n,)`` class names of the places the scans were taken in.
        regions: ``(n,)`` region ids (0: unknown; all 0 without a label map).
        label_map: the labelled map, if there is one.
        doors: the labelled doors.
        map_xy: ``(n, 2)`` where each scan lies in the labelled map's frame (metres), None
            without a map.
    """

    stamps: np.ndarray
    poses: np.ndarray
    labels: np.ndarray
    regions: np.ndarray
    label_map: LabelMap | None
    doors: tuple[Door, ...]
    map_xy: np.ndarray | None = None

    @classmethod
    def from_arrays(
        cls,
        stamps: np.ndarray,
        poses: np.ndarray,
        labels: np.ndarray,
        *,
        label_map: LabelMap | None = None,
        map_px: np.ndarray | None = None,
        map_xy: np.ndarray | None = None,
        door_merge: float = 0.7,
        min_stay: float = 0.5,
    ) -> Truth:
        """The truth from per-scan arrays (``labels``: codes or class names). Where each scan
        lies in the labelled map: ``map_px`` (pixels), ``map_xy`` (metres), else its pose.
        ``door_merge`` and ``min_stay`` (metres) as in :func:`_map_doors` and :func:`_run_doors`."""
        t = np.asarray(stamps, dtype=np.float64)
        p = np.asarray(poses, dtype=np.float64)
        lab = np.asarray(labels)
        names = lab.astype(object) if lab.dtype.kind in "OUS" else label_names(lab)
        n = t.shape[0]
        if p.shape != (n, 3) or names.shape != (n,):
            raise ValueError(
                f"stamps {t.shape}, poses {p.shape} and labels {names.shape} must describe n scans"
            )
        if n and not np.all(np.diff(t) > 0):
            raise ValueError("the labelled scans' stamps must increase strictly")
        regions = np.zeros(n, dtype=np.int64)
        xy = None
        if label_map is not None:
            if map_px is not None:
                px = np.asarray(map_px, dtype=np.int64).reshape(n, 2)
                xy = label_map.alignment.to_m(px.astype(np.float64))
            elif map_xy is not None:
                xy = np.asarray(map_xy, dtype=np.float64).reshape(n, 2)
            else:
                xy = p[:, :2]
            _, regions = label_map.place_at(xy)
            door_ids = label_map.door_at(xy)
            doors = _map_doors(label_map, xy, door_ids, regions, door_merge, min_stay)
        else:
            doors = _run_doors(p[:, :2], names, door_merge)
        return cls(t, p, names, regions.astype(np.int64), label_map, tuple(doors), xy)

    def within(self, t0: float, t1: float) -> Truth:
        """The truth of the scans stamped in ``[t0, t1]`` (a replay of part of the log: the
        doors it drove through are those of that stretch)."""
        sel = (self.stamps >= t0) & (self.stamps <= t1)
        if sel.all():
            return self
        return Truth.from_arrays(
            self.stamps[sel],
            self.poses[sel],
            self.labels[sel],
            label_map=self.label_map,
            map_xy=None if self.map_xy is None else self.map_xy[sel],
        )

    @classmethod
    def from_npz(cls, arrays: Mapping[str, np.ndarray], label_map_image: np.ndarray | None = None) -> Truth:
        """From the arrays of a per-scan label file (``np.load(path, allow_pickle=False)``);
        ``label_map_image`` is the labelled map its ``map_px``/``align`` refer to."""
        for key in ("t", "pose", "label"):
            if key not in arrays:
                raise ValueError(
                    f"a per-scan label file needs the arrays t, pose and label; {key!r} is missing"
                )
        label_map = None
        if label_map_image is not None:
            if "align" not in arrays:
                raise ValueError("a labelled map needs the alignment: the label file has no 'align'")
            label_map = LabelMap.from_image(label_map_image, Alignment.from_json(str(arrays["align"])))
        return cls.from_arrays(
            arrays["t"],
            arrays["pose"],
            arrays["label"],
            label_map=label_map,
            map_px=arrays["map_px"] if label_map is not None and "map_px" in arrays else None,
        )

    @classmethod
    def from_map(cls, label_map: LabelMap, stamps: np.ndarray, poses: np.ndarray) -> Truth:
        """Labels read off the map at the scans' poses (which must be in the aligned frame)."""
        p = np.asarray(poses, dtype=np.float64)
        names = label_map.class_at(p[:, :2])
        on_nothing = names == ""
        if on_nothing.any():  # on a wall or furniture in the drawn map: the place beside it
            names[on_nothing] = label_map.place_at(p[on_nothing, :2])[0]
        return cls.from_arrays(stamps, p, names, label_map=label_map)

    def place_of(self, xy: np.ndarray, radius: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
        """``(classes, regions)`` of the places at points (metres): the map's, else the
        majority truth of the labelled scans within ``radius`` (doorway scans left out)."""
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.label_map is not None:
            return self.label_map.place_at(pts)
        classes = np.full(pts.shape[0], "", dtype=object)
        keep = (self.labels != "doorway") & (self.labels != "")
        if keep.any():
            from scipy.spatial import cKDTree

            tree = cKDTree(self.poses[keep, :2])
            labels = self.labels[keep]
            for i, near in enumerate(tree.query_ball_point(pts, radius)):
                if near:
                    classes[i] = Counter(labels[near].tolist()).most_common(1)[0][0]
        return classes, np.zeros(pts.shape[0], dtype=np.int64)


def _map_doors(
    label_map: LabelMap,
    xy: np.ndarray,
    door_ids: np.ndarray,
    regions: np.ndarray,
    merge: float,
    min_stay: float,
) -> list[Door]:
    """The doors of a labelled map and of the path.

    A door the robot *drove through* is where its path passes from one region to another
    (through walls it cannot go): the scans in doorway pixels count as in no region, stays
    in a region shorter than ``min_stay`` metres of path are ignored (a path along a wall
    that the drawn map puts a little off flickers between its two sides), and the crossing
    is the midpoint between the last pose in the region left and the first in the region
    entered. Crossings within ``merge`` metres are one door. Drawn doors (doorway
    components) the path does not pass through are doors not driven through; a drawn door
    within ``merge`` of a crossing is that door.
    """
    reg = np.where(door_ids > 0, 0, regions)
    known = np.flatnonzero(reg > 0)
    step = np.r_[0.0, np.hypot(*np.diff(xy, axis=0).T)]
    path = np.cumsum(step)
    # runs of one region over the known scans: (region, first index, last index)
    runs: list[list[int]] = []
    for i in known:
        if runs and runs[-1][0] == reg[i]:
            runs[-1][2] = int(i)
        else:
            runs.append([int(reg[i]), int(i), int(i)])
    # a short stay between two runs is noise: merge it away (repeat until stable)
    changed = True
    while changed and len(runs) > 2:
        changed = False
        for k in range(1, len(runs) - 1):
            _, a, b = runs[k]
            if path[b] - path[a] < min_stay:
                del runs[k]
                if runs[k - 1][0] == runs[k][0]:  # A, short B, A: one stay in A
                    runs[k - 1][2] = runs[k][2]
                    del runs[k]
                changed = True
                break
    crossings = [
        (0.5 * (xy[runs[k][2]] + xy[runs[k + 1][1]]), {runs[k][0], runs[k + 1][0]})
        for k in range(len(runs) - 1)
    ]
    clusters: list[tuple[np.ndarray, int, set[int]]] = []
    for c, pair in crossings:
        for k, (total, m, regs) in enumerate(clusters):
            if np.hypot(*(total / m - c)) <= merge:
                clusters[k] = (total + c, m + 1, regs | pair)
                break
        else:
            clusters.append((c.copy(), 1, set(pair)))
    classes = label_map.region_class
    doors = [
        Door(k + 1, (float(t[0] / m), float(t[1] / m)), True, m, all(classes[r] == "room" for r in regs))
        for k, (t, m, regs) in enumerate(clusters)
    ]
    driven_xy = np.array([d.center for d in doors], dtype=np.float64).reshape(-1, 2)
    for centre in label_map.door_centres().values():
        if driven_xy.size and np.hypot(*(driven_xy - np.array(centre)).T).min() <= merge:
            continue
        doors.append(Door(len(doors) + 1, centre, False, 0))
    return doors


def _run_doors(xy: np.ndarray, labels: np.ndarray, merge: float) -> list[Door]:
    """Doors from runs of doorway-labelled scans (no map): a run's centre is the mean of its
    poses, runs within ``merge`` metres are one door; driven through when the labels before
    and after the run differ."""
    runs: list[tuple[np.ndarray, bool]] = []
    i, n = 0, labels.shape[0]
    while i < n:
        if labels[i] != "doorway":
            i += 1
            continue
        j = i
        while j < n and labels[j] == "doorway":
            j += 1
        before = labels[i - 1] if i > 0 else ""
        after = labels[j] if j < n else ""
        runs.append((xy[i:j].mean(axis=0), bool(before and after and before != after)))
        i = j
    doors: list[tuple[np.ndarray, int, int]] = []  # centre sum, runs, passages
    for centre, driven in runs:
        for k, (s, m, pas) in enumerate(doors):
            if np.hypot(*(s / m - centre)) <= merge:
                doors[k] = (s + centre, m + 1, pas + int(driven))
                break
        else:
            doors.append((centre.copy(), 1, int(driven)))
    return [
        Door(k + 1, (float(s[0] / m), float(s[1] / m)), pas > 0, pas) for k, (s, m, pas) in enumerate(doors)
    ]


def match_stamps(truth: np.ndarray, stamps: np.ndarray, tolerance: float) -> np.ndarray:
    """For each stamp, the index of the truth stamp nearest to it within ``tolerance`` seconds
    (-1: none). ``truth`` increases strictly."""
    t = np.asarray(truth, dtype=np.float64)
    s = np.asarray(stamps, dtype=np.float64)
    if t.size == 0:
        return np.full(s.shape, -1, dtype=np.int64)
    i = np.searchsorted(t, s).clip(1, t.size - 1) if t.size > 1 else np.zeros(s.shape, dtype=np.int64)
    if t.size > 1:
        left_closer = np.abs(s - t[i - 1]) <= np.abs(t[i] - s)
        i = np.where(left_closer, i - 1, i)
    return np.where(np.abs(t[i] - s) <= tolerance, i, -1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class LogScores:
    """What :func:`evaluate` measured (see the module docstring); :meth:`as_dict` for JSON."""

    scans_labelled: int
    scans_in_span: int
    scans_scored: int
    two_class: Scores
    three_class: Scores
    majority_two: float
    majority_class: str
    nodes: Scores
    nodes_unlabelled: int
    doors: dict[str, Any]
    areas: dict[str, Any]

    def as_dict(self) -> dict[str, Any]:
        return {
            "scans": {
                "labelled": self.scans_labelled,
                "in_span": self.scans_in_span,
                "scored": self.scans_scored,
                "room_corridor": self.two_class.as_dict(),
                "three_class": self.three_class.as_dict(),
                "always_" + self.majority_class: round(self.majority_two, 6),
            },
            "nodes": {**self.nodes.as_dict(), "unlabelled": self.nodes_unlabelled},
            "doorways": self.doors,
            "areas": self.areas,
        }


def evaluate(
    truth: Truth,
    stamps: np.ndarray,
    predicted: Sequence[str],
    graph: Mapping[str, Any],
    areas: Mapping[str, Any] | None,
    *,
    stamp_tolerance: float = 0.01,
    door_radius: float = 0.7,
    node_radius: float = 0.5,
    area_purity: float = 0.8,
) -> LogScores:
    """Score a replay (see the module docstring).

    Args:
        truth: the ground truth.
        stamps: ``(m,)`` stamps of the scans the replay processed.
        predicted: their labels.
        graph: the final ``loci.graph/1`` message (node positions in the log's frame).
        areas: the final ``loci.areas/1`` message.
        stamp_tolerance: seconds; a processed scan and a labelled one are the same scan when
            their stamps differ by at most this.
        door_radius: metres between a door and its doorway node.
        node_radius: metres around a node whose labelled scans say its class (no map).
        area_purity: share of an area's nodes that must lie in a room for the room to be its
            own area.

    Raises:
        ValueError: no processed scan matches a labelled one.
    """
    s = np.asarray(stamps, dtype=np.float64)
    pred = np.asarray(list(predicted), dtype=object)
    labelled = int(truth.stamps.size)
    if s.size:
        truth = truth.within(float(s.min()) - stamp_tolerance, float(s.max()) + stamp_tolerance)
    idx = match_stamps(truth.stamps, s, stamp_tolerance) if truth.stamps.size else np.full(s.shape, -1)
    ok = idx >= 0
    if not ok.any():
        first = f"{s[0]:.3f}" if s.size else "none"
        raise ValueError(
            f"no processed scan has a labelled stamp within {stamp_tolerance} s (first processed: {first}); "
            "are the labels for this log, on the same clock?"
        )
    t_lab = truth.labels[idx[ok]]
    p_lab = _as_two(pred[ok])
    two = score(_as_two(t_lab), p_lab, TWO_CLASSES)
    three = score(_as_two(t_lab), p_lab, THREE_CLASSES)
    counts = Counter(x for x in _as_two(t_lab).tolist() if x in TWO_CLASSES)
    majority, n_major = counts.most_common(1)[0] if counts else ("corridor", 0)
    nodes_score, unlabelled = _score_nodes(truth, graph, node_radius)
    return LogScores(
        scans_labelled=labelled,
        scans_in_span=int(truth.stamps.size),
        scans_scored=int(ok.sum()),
        two_class=two,
        three_class=three,
        majority_two=n_major / max(1, sum(counts.values())),
        majority_class=majority,
        nodes=nodes_score,
        nodes_unlabelled=unlabelled,
        doors=_score_doors(truth, graph, door_radius),
        areas=_score_areas(truth, graph, areas, area_purity),
    )


def _place_nodes(graph: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    return [n for n in graph["nodes"] if n["kind"] != "doorway"]


def _score_nodes(truth: Truth, graph: Mapping[str, Any], radius: float) -> tuple[Scores, int]:
    nodes = _place_nodes(graph)
    xy = np.array([[n["x"], n["y"]] for n in nodes], dtype=np.float64).reshape(-1, 2)
    classes, _ = truth.place_of(xy, radius)
    pred = np.array([n["label"] or "" for n in nodes], dtype=object)
    unlabelled = int(sum(1 for n in nodes if n["label"] is None))
    return score(_as_two(classes), _as_two(pred), TWO_CLASSES), unlabelled


def _score_doors(truth: Truth, graph: Mapping[str, Any], radius: float) -> dict[str, Any]:
    door_nodes = [n for n in graph["nodes"] if n["kind"] == "doorway"]
    dn = np.array([[n["x"], n["y"]] for n in door_nodes], dtype=np.float64).reshape(-1, 2)
    centres = np.array([d.center for d in truth.doors], dtype=np.float64).reshape(-1, 2)
    driven = [d for d in truth.doors if d.driven and not d.room_to_room]
    found = []
    for d in driven:
        near = np.hypot(*(dn - np.array(d.center)).T) <= radius if dn.size else np.zeros(0, bool)
        found.append(bool(np.any(near)))
    false_nodes = []
    for n, p in zip(door_nodes, dn, strict=True):
        if not centres.size or np.hypot(*(centres - p).T).min() > radius:
            false_nodes.append(int(n["id"]))
    n_found = int(sum(found))
    return {
        "doors_labelled": len(truth.doors),
        "doors_driven_through": len(driven),
        "room_to_room_crossings": sum(d.driven and d.room_to_room for d in truth.doors),
        "doors_found": n_found,
        "recall": round(n_found / len(driven), 6) if driven else None,
        "doorway_nodes": len(door_nodes),
        "false_doorway_nodes": len(false_nodes),
        "false_share": round(len(false_nodes) / len(door_nodes), 6) if door_nodes else None,
        "missed": [
            {"id": d.id, "x": round(d.center[0], 3), "y": round(d.center[1], 3)}
            for d, f in zip(driven, found, strict=True)
            if not f
        ],
        "false": false_nodes,
        "radius": radius,
    }


def _score_areas(
    truth: Truth, graph: Mapping[str, Any], areas: Mapping[str, Any] | None, purity: float
) -> dict[str, Any]:
    area_list = [a for a in (areas or {}).get("areas", []) if a.get("nodes")]
    out: dict[str, Any] = {"areas": len(area_list)}
    if truth.label_map is None:
        out["note"] = "regions unknown (no labelled map): areas are not scored against rooms"
        return out
    nodes = {int(n["id"]): n for n in _place_nodes(graph)}
    ids = sorted(nodes)
    xy = np.array([[nodes[k]["x"], nodes[k]["y"]] for k in ids], dtype=np.float64).reshape(-1, 2)
    _, reg = truth.label_map.place_at(xy)
    region_of = {k: int(r) for k, r in zip(ids, reg, strict=True)}
    area_of = {int(k): int(a["id"]) for a in area_list for k in a["nodes"]}
    pairs: Counter[tuple[int, int]] = Counter()
    for k in ids:
        if region_of[k] and k in area_of:
            pairs[(region_of[k], area_of[k])] += 1
    region_size: Counter[int] = Counter(r for r in region_of.values() if r)
    area_size: Counter[int] = Counter(area_of[k] for k in ids if k in area_of and region_of[k])
    region_class = truth.label_map.region_class
    rooms = sorted(r for r in region_size if region_class[r] == "room")
    own, detail = 0, []
    for r in rooms:
        best_area, best = max(
            ((a, c) for (rr, a), c in pairs.items() if rr == r), key=lambda t: (t[1], -t[0]), default=(0, 0)
        )
        share_of_room = best / region_size[r]
        share_of_area = best / area_size[best_area] if best_area else 0.0
        is_own = share_of_room >= 0.5 and share_of_area >= purity
        own += is_own
        detail.append(
            {
                "region": r,
                "nodes": region_size[r],
                "area": best_area or None,
                "share_of_room": round(share_of_room, 4),
                "area_purity": round(share_of_area, 4),
                "own_area": is_own,
            }
        )
    best_of_region = {r: max((c for (rr, _), c in pairs.items() if rr == r), default=0) for r in region_size}
    best_of_area = {a: max((c for (_, aa), c in pairs.items() if aa == a), default=0) for a in area_size}
    recall = [best_of_region[r] / region_size[r] for r in region_size]
    precision = [best_of_area[a] / area_size[a] for a in area_size]
    total = sum(region_size.values())
    out.update(
        {
            "regions_visited": len(region_size),
            "rooms_visited": len(rooms),
            "rooms_with_own_area": own,
            "own_area_share": round(own / len(rooms), 6) if rooms else None,
            "recall_mean": round(float(np.mean(recall)), 6) if recall else None,
            "precision_mean": round(float(np.mean(precision)), 6) if precision else None,
            "recall_pooled": round(sum(best_of_region.values()) / total, 6) if total else None,
            "precision_pooled": round(sum(best_of_area.values()) / total, 6) if total else None,
            "rooms": detail,
            "purity": purity,
        }
    )
    return out
