"""The legs data (``../shared/data/legs``, see its README) and the train/test protocol.

Files (from leg_tracker, A. Leigh; a 270° laser, 768 beams): ``positive_<n>_extracted.
training_scan.npz`` with labelled leg centroids, and ``negative_2.<laser>_scan.npz`` in which
nobody is present. Arrays: ``ranges`` (scans × beams, metres; inf/0 = no return),
``stamp_ns``, ``angle_min``, ``angle_increment``, ``range_max`` and, in positive files,
``legs`` (rows of scan index, x, y in metres in the laser frame).

The protocol (issue 7):

* TRAIN = positive_1..4 (all scans) + the first 70 % of the scans of negative_2;
  TEST = positive_6..7 + the remaining 30 % of negative_2.
* negative_2 exists for three lasers (left, rear, right), recorded at the same time. All
  three are used; each is split at 70 % of its own scans, so train and test come from
  disjoint time spans (the split falls within one scan period across the three).
* Only segments with at least two points are examples (Sect. 8.2).
* A segment is positive when its centroid lies within 5 cm of a labelled leg. In positive
  files, other segments whose centroid lies in the labelled arc are negatives; segments outside
  it are ignored. The arc is ``min_deg < bearing < max_deg`` and ``distance < 5 m`` (strict, as
  the labelling tool tested it) around the laser's x axis: ±15°, except positive_4, which the
  labelling tool extracted with ``max_angle = 10°`` (leg_tracker's
  ``extract_positive_training_clusters_res=0.33.launch``; its labels never exceed 9.8°).
* In negative files every segment is a negative.
* Readings below :data:`LEGS_RANGE_MIN` (the laser's error codes, 6–15 mm) are no returns.

Timestamps: in the positive files ``stamp_ns`` are ~1 ms apart — the time the extraction
tool wrote the scans, not when they were measured (legs move ~0.1 m between consecutive
scans, which at walking speed means ~0.1 s). Files whose median stamp step is below
:data:`MIN_PLAUSIBLE_PERIOD` use :data:`NOMINAL_PERIOD` (the median step of negative_2,
133 ms) as the time between scans for C.14.
"""

from __future__ import annotations

import math
import zipfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.errors import DataError
from knowledge.people.features import N_FEATURES, segment_features
from knowledge.people.segmentation import DEFAULT_JUMP, FloatArray, Segmentation, segment_scan

#: Sub-folder of the data folder that holds the legs files.
LEGS_SUBDIR = "legs"
POSITIVE_PATTERN = "positive_{n}_extracted.training_scan.npz"
NEGATIVE_PATTERN = "negative_2.{laser}_scan.npz"
TRAIN_POSITIVES = (1, 2, 3, 4)
TEST_POSITIVES = (6, 7)
NEGATIVE_LASERS = ("left", "rear", "right")
#: Fraction of each negative file's scans (the first ones) that go to TRAIN.
TRAIN_FRACTION = 0.7
#: A segment whose centroid lies this close to a labelled leg (metres) is a leg.
MATCH_RADIUS = 0.05
#: Labelled arc ``(min_deg, max_deg, max_dist_m)``.
DEFAULT_ARC = (-15.0, 15.0, 5.0)
ARCS: dict[str, tuple[float, float, float]] = {"positive_4": (-15.0, 10.0, 5.0)}
#: Fewest points of a segment the detector classifies (book Sect. 8.2).
MIN_POINTS = 2
#: Minimum range of the legs data's laser, metres (not stored in the files). Its Hokuyo reports
#: errors as ranges of 6–15 mm; leg_tracker, which made the labels, dropped the readings below
#: the scans' ``range_min`` — with 0.02 m its clustering reproduces all 1852 labels exactly.
LEGS_RANGE_MIN = 0.02
#: Median stamp steps below this (seconds) are not acquisition times.
MIN_PLAUSIBLE_PERIOD = 0.005
#: Seconds between scans when the stamps are not usable (median step of negative_2).
NOMINAL_PERIOD = 0.133
#: In-arc negatives within this distance (metres) of a labelled leg are counted as "near a leg".
NEAR_LEG = 0.3

#: Example labels.
POSITIVE, NEGATIVE, IGNORED = 1, 0, -1


def find_legs_dir(data: str | Path) -> Path:
    """The folder holding the legs files: ``data/legs``, or ``data`` itself if it holds them.

    Raises :class:`DataError` saying what to pass.
    """
    root = Path(data)
    for cand in (root / LEGS_SUBDIR, root):
        if cand.is_dir() and any(cand.glob("positive_*_extracted.training_scan.npz")):
            return cand
    raise DataError(
        f"no legs data in {root} (expected {root / LEGS_SUBDIR}/positive_1_extracted.training_scan.npz ...): "
        "pass --data DIR (the shared data folder or its legs/ sub-folder) or set LOCI_DATA"
    )


@dataclass(frozen=True, eq=False)
class LegsRecording:
    """One file of the legs data.

    Attributes:
        name: ``positive_1`` … or ``negative_2.left`` …
        ranges: ``(S, B)`` float32 metres.
        stamps: ``(S,)`` float64 seconds as stored.
        angle_min, angle_increment: radians; range_max, range_min: metres.
        legs: ``(K, 3)`` float64 rows (scan, x, y) for positive files, None for negative ones.
        period: seconds between consecutive scans used for C.14 (see the module doc).
    """

    name: str
    ranges: npt.NDArray[np.float32]
    stamps: FloatArray
    angle_min: float
    angle_increment: float
    range_max: float
    legs: FloatArray | None
    period: float
    range_min: float = LEGS_RANGE_MIN
    _legs_by_scan: dict[int, FloatArray] = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_scans(self) -> int:
        return int(self.ranges.shape[0])

    @property
    def positive(self) -> bool:
        return self.legs is not None

    @property
    def arc(self) -> tuple[float, float, float]:
        """``(min_deg, max_deg, max_dist)`` of the labelled arc."""
        return ARCS.get(self.name, DEFAULT_ARC)

    def legs_in(self, scan: int) -> FloatArray:
        """``(k, 2)`` labelled leg centroids of one scan (metres, laser frame)."""
        if self.legs is None:
            return np.zeros((0, 2))
        if not self._legs_by_scan:
            idx = self.legs[:, 0].astype(np.intp)
            for s in np.unique(idx).tolist():
                self._legs_by_scan[int(s)] = self.legs[idx == s, 1:3]
        return self._legs_by_scan.get(int(scan), np.zeros((0, 2)))


def load_recording(path: str | Path) -> LegsRecording:
    """Read one legs file (``allow_pickle=False``); :class:`DataError` if it is unusable."""
    p = Path(path)
    name = (
        p.name.split("_extracted")[0] if p.name.startswith("positive_") else p.name.removesuffix("_scan.npz")
    )
    try:
        with np.load(p, allow_pickle=False) as z:
            ranges = np.asarray(z["ranges"], dtype=np.float32)
            stamps = np.asarray(z["stamp_ns"], dtype=np.float64) * 1e-9
            angle_min = float(z["angle_min"])
            inc = float(z["angle_increment"])
            range_max = float(z["range_max"])
            legs = np.asarray(z["legs"], dtype=np.float64) if "legs" in z.files else None
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise DataError(f"{p}: not a readable legs file ({exc}); see the data folder's README") from exc
    if ranges.ndim != 2 or stamps.shape != (ranges.shape[0],):
        raise DataError(f"{p}: ranges {ranges.shape} and stamp_ns {stamps.shape} do not fit together")
    steps = np.diff(stamps)
    median = float(np.median(steps)) if steps.size else 0.0
    period = median if median >= MIN_PLAUSIBLE_PERIOD else NOMINAL_PERIOD
    return LegsRecording(name, ranges, stamps, angle_min, inc, range_max, legs, period)


@dataclass(frozen=True)
class Part:
    """Scans ``[first, stop)`` of one file of the protocol."""

    file: str
    first: int = 0
    stop: int | None = None


def protocol_parts(split: str, legs_dir: Path, *, max_scans: int | None = None) -> list[Part]:
    """The files and scan ranges of ``split`` ("train" or "test") of the protocol.

    ``max_scans`` keeps at most that many scans of each part (the first ones), for quick runs.
    """
    if split not in ("train", "test"):
        raise ValueError(f'split must be "train" or "test", got {split!r}')
    positives = TRAIN_POSITIVES if split == "train" else TEST_POSITIVES
    parts = [Part(POSITIVE_PATTERN.format(n=n)) for n in positives]
    for laser in NEGATIVE_LASERS:
        f = NEGATIVE_PATTERN.format(laser=laser)
        n = _n_scans(legs_dir / f)
        cut = math.floor(TRAIN_FRACTION * n)
        parts.append(Part(f, 0, cut) if split == "train" else Part(f, cut, n))
    if max_scans is not None:
        if max_scans < 1:
            raise ValueError(f"max_scans must be >= 1, got {max_scans}")
        out = []
        for part in parts:
            stop = part.stop if part.stop is not None else _n_scans(legs_dir / part.file)
            out.append(Part(part.file, part.first, min(stop, part.first + max_scans)))
        parts = out
    return parts


def _n_scans(path: Path) -> int:
    if not path.is_file():
        raise DataError(f"{path}: missing; the legs data folder is incomplete (see its README)")
    try:
        with np.load(path, allow_pickle=False) as z:
            return int(z["stamp_ns"].shape[0])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise DataError(f"{path}: not a readable legs file ({exc})") from exc


def label_segments(
    rec: LegsRecording, scan: int, centroids: FloatArray, sizes: npt.NDArray[np.intp]
) -> tuple[npt.NDArray[np.int8], dict[str, int]]:
    """Protocol labels of one scan's segments: ``(S,)`` int8 POSITIVE / NEGATIVE / IGNORED.

    Also returns counts for diagnostics: ``legs`` labelled, ``legs_matched`` (a segment of ≥ 2
    points within 5 cm), ``near_leg_negatives`` (in-arc negatives within 0.3 m of a leg).
    """
    S = centroids.shape[0]
    labels = np.full(S, IGNORED, dtype=np.int8)
    usable = sizes >= MIN_POINTS
    if not rec.positive:
        labels[usable] = NEGATIVE
        return labels, {"legs": 0, "legs_matched": 0, "near_leg_negatives": 0}
    legs = rec.legs_in(scan)
    if legs.shape[0]:
        dist = np.hypot(centroids[:, None, 0] - legs[None, :, 0], centroids[:, None, 1] - legs[None, :, 1])
        nearest = dist.min(axis=1)
        matched = usable & (nearest <= MATCH_RADIUS)
        legs_matched = int((dist[usable] <= MATCH_RADIUS).any(axis=0).sum())
    else:
        nearest = np.full(S, np.inf)
        matched = np.zeros(S, dtype=bool)
        legs_matched = 0
    lo, hi, max_dist = rec.arc
    bearing = np.degrees(np.arctan2(centroids[:, 1], centroids[:, 0]))
    in_arc = (bearing > lo) & (bearing < hi) & (np.hypot(centroids[:, 0], centroids[:, 1]) < max_dist)
    negative = usable & in_arc & ~matched
    labels[negative] = NEGATIVE
    labels[matched] = POSITIVE
    return labels, {
        "legs": int(legs.shape[0]),
        "legs_matched": legs_matched,
        "near_leg_negatives": int((negative & (nearest <= NEAR_LEG)).sum()),
    }


@dataclass(frozen=True, eq=False)
class Examples:
    """Labelled segments of a split.

    Attributes:
        X: ``(n, 14)`` float64 features C.1–C.14 of every example.
        y: ``(n,)`` bool, True for a leg (person).
        part: ``(n,)`` index into ``parts``; scan: ``(n,)`` scan index in its file;
        segment: ``(n,)`` segment index in its scan.
        distance: ``(n,)`` distance of the segment's centroid from the laser, metres.
        parts: the protocol parts the examples came from.
        diagnostics: counts over the split (see :func:`label_segments`), plus ``scans``.
    """

    X: FloatArray
    y: npt.NDArray[np.bool_]
    part: npt.NDArray[np.intp]
    scan: npt.NDArray[np.intp]
    segment: npt.NDArray[np.intp]
    distance: FloatArray
    parts: tuple[Part, ...]
    diagnostics: dict[str, Any]

    @property
    def n_positive(self) -> int:
        return int(self.y.sum())

    @property
    def n_negative(self) -> int:
        return int((~self.y).sum())


def iter_scan_features(
    rec: LegsRecording,
    first: int = 0,
    stop: int | None = None,
    *,
    jump: float = DEFAULT_JUMP,
    max_gap: int | None = None,
) -> Iterator[tuple[int, Segmentation, FloatArray]]:
    """``(scan, segmentation, features (S, 14))`` for scans ``[first, stop)`` of a recording.

    C.14 uses the scan before each one (also for ``first``, when it exists) and
    ``rec.period`` seconds between them.
    """
    stop = rec.n_scans if stop is None else stop
    for k in range(first, stop):
        seg = segment_scan(
            rec.ranges[k],
            rec.angle_min,
            rec.angle_increment,
            range_max=rec.range_max,
            range_min=rec.range_min,
            jump=jump,
            max_gap=max_gap,
        )
        prev = rec.ranges[k - 1] if k > 0 else None
        X = segment_features(
            seg,
            range_max=rec.range_max,
            range_min=rec.range_min,
            previous=prev,
            dt=rec.period if k > 0 else None,
        )
        yield k, seg, X


def build_examples(
    legs_dir: Path,
    parts: Sequence[Part],
    *,
    jump: float = DEFAULT_JUMP,
    max_gap: int | None = None,
    progress: Callable[[Iterable[Any]], Iterable[Any]] | None = None,
) -> Examples:
    """Segment, featurise and label every scan of ``parts`` (see the module doc).

    ``progress`` wraps the iteration over scans (e.g. ``functools.partial(tqdm, total=...)``).
    """
    recs: dict[str, LegsRecording] = {}
    Xs: list[FloatArray] = []
    ys: list[npt.NDArray[np.bool_]] = []
    meta: list[npt.NDArray[np.intp]] = []
    dists: list[FloatArray] = []
    diag = {"scans": 0, "legs": 0, "legs_matched": 0, "near_leg_negatives": 0, "ignored_segments": 0}

    def scans() -> Iterator[tuple[int, LegsRecording, int, Segmentation, FloatArray]]:
        for pi, part in enumerate(parts):
            if part.file not in recs:
                path = legs_dir / part.file
                if not path.is_file():
                    raise DataError(f"{path}: missing; the legs data folder is incomplete (see its README)")
                recs[part.file] = load_recording(path)
            rec = recs[part.file]
            for k, seg, X in iter_scan_features(rec, part.first, part.stop, jump=jump, max_gap=max_gap):
                yield pi, rec, k, seg, X

    it: Iterable[tuple[int, LegsRecording, int, Segmentation, FloatArray]] = scans()
    if progress is not None:
        it = progress(it)
    for pi, rec, k, seg, X in it:
        centroids = seg.centroids()
        labels, counts = label_segments(rec, k, centroids, seg.sizes)
        for key, v in counts.items():
            diag[key] += v
        diag["scans"] += 1
        keep = labels != IGNORED
        diag["ignored_segments"] += int((~keep).sum())
        idx = np.flatnonzero(keep)
        Xs.append(X[idx])
        ys.append(labels[idx] == POSITIVE)
        dists.append(np.hypot(centroids[idx, 0], centroids[idx, 1]))
        meta.append(np.column_stack([np.full(idx.size, pi), np.full(idx.size, k), idx]).astype(np.intp))
    M = np.concatenate(meta) if meta else np.zeros((0, 3), dtype=np.intp)
    return Examples(
        X=np.concatenate(Xs) if Xs else np.zeros((0, N_FEATURES)),
        y=np.concatenate(ys) if ys else np.zeros(0, dtype=bool),
        part=M[:, 0],
        scan=M[:, 1],
        segment=M[:, 2],
        distance=np.concatenate(dists) if dists else np.zeros(0),
        parts=tuple(parts),
        diagnostics=diag,
    )


def n_protocol_scans(legs_dir: Path, parts: Sequence[Part]) -> int:
    """Total scans in ``parts`` (for progress bars)."""
    total = 0
    for part in parts:
        stop = part.stop if part.stop is not None else _n_scans(legs_dir / part.file)
        total += stop - part.first
    return total


#: A segment whose centroid is this near (metres) an annotated person is one of their legs...
PERSON_LEG_RADIUS = 0.3
#: ...if it is at most this wide (C.6, metres): both legs and what stands beside them are not.
PERSON_LEG_WIDTH = 0.45
#: Segments farther than this (metres) from every annotated person are non-people.
PERSON_CLEAR_RADIUS = 1.0


def label_person_annotations(
    features: FloatArray,
    centroids: FloatArray,
    people: FloatArray,
    *,
    arc_deg: tuple[float, float] | None = None,
) -> npt.NDArray[np.int8]:
    """Labels of one scan's segments from annotated *people* (not legs), as in the leg_tracker
    benchmark bags: ``(S,)`` int8 POSITIVE / NEGATIVE / IGNORED.

    ``features`` ``(S, 14)`` and ``centroids`` ``(S, 2)`` of the scan's segments (sensor
    frame, metres); ``people`` ``(G, 2)`` the annotated people's positions (the midpoint of
    their legs) in the same frame. A segment of at least two points is a positive when its
    centroid lies within :data:`PERSON_LEG_RADIUS` of a person and it is at most
    :data:`PERSON_LEG_WIDTH` wide; a negative when it is farther than
    :data:`PERSON_CLEAR_RADIUS` from every person and (with ``arc_deg``) its bearing lies in
    the annotated arc; everything else (wide segments at a person, segments between the two
    radii, outside the arc) is ignored. The annotators marked everybody in the arc, so what is
    not near a person there is not a person.
    """
    S = centroids.shape[0]
    labels = np.full(S, IGNORED, dtype=np.int8)
    if S == 0:
        return labels
    usable = features[:, 0] >= MIN_POINTS
    if people.shape[0]:
        d = np.hypot(centroids[:, None, 0] - people[None, :, 0], centroids[:, None, 1] - people[None, :, 1])
        nearest = d.min(axis=1)
    else:
        nearest = np.full(S, np.inf)
    in_arc = np.ones(S, dtype=bool)
    if arc_deg is not None:
        bearing = np.degrees(np.arctan2(centroids[:, 1], centroids[:, 0]))
        in_arc = (bearing >= arc_deg[0]) & (bearing <= arc_deg[1])
    labels[usable & in_arc & (nearest > PERSON_CLEAR_RADIUS)] = NEGATIVE
    labels[usable & (nearest <= PERSON_LEG_RADIUS) & (features[:, 5] <= PERSON_LEG_WIDTH)] = POSITIVE
    return labels
