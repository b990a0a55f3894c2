"""People tracks from a recording, and the annotated people of a benchmark bag (the I/O side).

:func:`track_recording` runs the agent's people step over a recording, offline: the
recorded scans and odometry go through the same :class:`~agent.core.odom_sync.OdomSync` as in
``loci run`` (an imported log: ``reorder`` 1 s, as ``loci replay``), each scan gets the
laser's odometry pose (the robot's pose composed with the recorded mount, as
:class:`~agent.core.pipeline.Pipeline` does) and is handed to a
:class:`~knowledge.people.pipeline.PeoplePipeline`: people are tracked in the odometry frame
while the robot moves. Each processed scan becomes a :class:`TrackFrame`; a file of them is
JSON lines (:func:`write_tracks`, :func:`read_tracks`).

:func:`read_annotations` reads a leg_tracker benchmark bag's hand-annotated people
(``/ground_truth_people_tracks``, ``leg_tracker/Person``: an id and a position, no header)
with ``rosbags`` and gives each the scan it was annotated on: the annotation tool writes it at
the midpoint between that scan and the next one (bag times), in the laser's frame
(``left_laser`` in the benchmark), and the benchmark's scorer takes every annotation between
two scans for the first of them. Scans are named by their header stamp, which is what a
recording imported with ``loci import`` keeps.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from knowledge.errors import DataError

__all__ = [
    "ANNOTATION_TOPIC",
    "BENCHMARK_ARC",
    "TRACKS_SCHEMA",
    "Annotations",
    "TrackFrame",
    "TrackRun",
    "TrackScores",
    "bag_examples",
    "bag_segments",
    "read_annotations",
    "read_bag_scans",
    "read_tracks",
    "recording_scans",
    "score_tracks",
    "track_recording",
    "track_scans",
    "write_tracks",
]

TRACKS_SCHEMA = "loci.people-tracks/1"
ANNOTATION_TOPIC = "/ground_truth_people_tracks"
PERSON_TYPE = "leg_tracker/msg/Person"
#: Seconds within which two stamps name the same scan.
STAMP_TOLERANCE = 1e-4


@dataclass(frozen=True, eq=False)
class TrackFrame:
    """What the people step gave for one scan.

    Attributes:
        stamp: the scan's stamp, seconds.
        sensor_pose: the laser's pose ``(x, y, θ)`` in the odometry frame (metres, radians).
        people: ``(P, 2)`` this scan's detected people (paired legs), odometry frame, metres.
        tracks: ``(T, 5)`` the confirmed tracks reported after this scan: id, x, y (odometry
            frame, metres), misses (scans missed in a row, 0 = seen now), travelled (metres).
    """

    stamp: float
    sensor_pose: tuple[float, float, float]
    people: np.ndarray
    tracks: np.ndarray

    def to_json(self) -> dict[str, Any]:
        return {
            "stamp": self.stamp,
            "sensor_pose": list(self.sensor_pose),
            "people": [[round(float(x), 4), round(float(y), 4)] for x, y in self.people],
            "tracks": [
                {
                    "id": int(t[0]),
                    "x": round(float(t[1]), 4),
                    "y": round(float(t[2]), 4),
                    "misses": int(t[3]),
                    "travelled": round(float(t[4]), 3),
                }
                for t in self.tracks
            ],
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> TrackFrame:
        pose = d["sensor_pose"]
        people = np.asarray(d["people"], dtype=np.float64).reshape(-1, 2)
        tracks = np.array(
            [(t["id"], t["x"], t["y"], t.get("misses", 0), t.get("travelled", 0.0)) for t in d["tracks"]],
            dtype=np.float64,
        ).reshape(-1, 5)
        if len(pose) != 3:
            raise ValueError(f"sensor_pose must be (x, y, theta), got {pose!r}")
        frame = cls(float(d["stamp"]), (float(pose[0]), float(pose[1]), float(pose[2])), people, tracks)
        if not (np.isfinite(people).all() and np.isfinite(tracks).all() and math.isfinite(frame.stamp)):
            raise ValueError("stamp, people and tracks must be finite")
        return frame

    def in_sensor_frame(self, points: np.ndarray) -> np.ndarray:
        """``(K, 2)`` odometry-frame points in the laser's frame at this scan."""
        x, y, th = self.sensor_pose
        c, s = math.cos(th), math.sin(th)
        dx, dy = points[:, 0] - x, points[:, 1] - y
        return np.column_stack([c * dx + s * dy, -s * dx + c * dy])


@dataclass
class TrackRun:
    """A run of :func:`track_recording`: the frames and what happened to every scan.

    ``scans == len(frames) + invalid + sum(dropped.values())``.
    """

    frames: list[TrackFrame] = field(default_factory=list)
    scans: int = 0
    odometry: int = 0
    invalid: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)
    robot: str = ""
    seconds_people: float = 0.0

    def summary(self) -> dict[str, Any]:
        return {
            "scans": self.scans,
            "processed": len(self.frames),
            "invalid": self.invalid,
            "dropped": dict(self.dropped),
            "odometry": self.odometry,
            "mount": list(self.mount),
            "robot": self.robot,
            "people_seconds": self.seconds_people,
        }


def track_recording(
    path: str | Path,
    pipeline: Any,
    *,
    robot: str | None = None,
    progress: Callable[[int, int | None], None] | None = None,
) -> TrackRun:
    """Run ``pipeline`` (a :class:`~knowledge.people.pipeline.PeoplePipeline`) over a recording's
    scans with the laser's odometry pose (see the module doc).

    Raises:
        DataError: not an MCAP recording, or no scans of the robot.
    """
    run = TrackRun()
    return track_scans(recording_scans(path, run, robot=robot, progress=progress), pipeline, run)


def track_scans(
    scans: Iterable[tuple[Any, tuple[float, float, float]]], pipeline: Any, run: TrackRun
) -> TrackRun:
    """Hand each ``(scan, laser pose)`` to ``pipeline`` and append its frame to ``run`` (returned).

    :func:`track_recording` is this over :func:`recording_scans`; an evaluation that tracks one
    recording many times reads it once (``list(recording_scans(...))``) and calls this with a
    copy of the run's accounting each time: the frames are the same.
    """
    import time

    for scan, pose in scans:
        t0 = time.perf_counter()
        fr = pipeline.process_scan(scan, sensor_pose=pose)
        run.seconds_people += time.perf_counter() - t0
        tracks = np.array(
            [(t.id, t.position[0], t.position[1], t.misses, t.travelled) for t in fr.tracks],
            dtype=np.float64,
        ).reshape(-1, 5)
        run.frames.append(TrackFrame(fr.stamp, pose, fr.people.positions.copy(), tracks))
    return run


def recording_scans(
    path: str | Path,
    run: TrackRun,
    *,
    robot: str | None = None,
    progress: Callable[[int, int | None], None] | None = None,
) -> Iterator[tuple[Any, tuple[float, float, float]]]:
    """The scans of a recording with the laser's odometry pose, as the agent matches them (see
    the module doc), in order; ``run``'s accounting (scans, odometry, drops, mount, robot) is
    filled in while they are read (complete once the iterator is exhausted).

    Raises:
        DataError: not an MCAP recording, or no scans of the robot.
    """
    from agent.core.odom_sync import DROP_REASONS, SyncParams
    from agent.core.pipeline import PipelineParams, compose
    from agent.core.sensor_loop import SensorLoop
    from agent.recording.feed import RecordingFeed
    from agent.recording.importer import as_loci_recording
    from agent.recording.offline import (
        FOREIGN_REORDER,
        _message_count,
        read_recording_metadata,
        recorded_sync_params,
    )

    p = as_loci_recording(Path(path))
    if not p.is_file():
        raise DataError(f"{p}: no such recording")
    meta = read_recording_metadata(p)
    feed = RecordingFeed(p, robot=robot, meta=meta)
    params = (
        PipelineParams.from_table(json.loads(meta["pipeline"])) if meta.get("pipeline") else PipelineParams()
    )
    run.mount = tuple(float(v) for v in params.mount)  # type: ignore[assignment]
    run.robot = feed.robot
    total = _message_count(p, feed.keys.scan)
    posed: list[tuple[Any, tuple[float, float, float]]] = []

    def step(m: Any) -> None:
        sensor = compose(m.pose, params.mount)
        posed.append((m.scan, (float(sensor[0]), float(sensor[1]), float(sensor[2]))))

    # the agent's own sensor loop, so the tracks see the scans and poses a replay does
    loop = SensorLoop(
        recorded_sync_params(meta) or SyncParams(reorder=FOREIGN_REORDER), step, max_rate=params.max_rate
    )
    for message in feed:
        loop.feed(message)
        yield from posed
        posed.clear()
        if progress is not None and message.kind == "scan":
            progress(feed.scans, total)
    loop.close()
    yield from posed
    run.scans, run.odometry, run.invalid = feed.scans, feed.odometry, feed.invalid_scans
    if feed.scans == 0:
        raise DataError(f"{p}: no {feed.keys.scan} messages")
    stats = loop.sync.stats.as_dict()
    run.dropped = {r: int(stats.get(r, 0)) for r in DROP_REASONS if stats.get(r, 0)}


def write_tracks(path: Path, run: TrackRun, header: dict[str, Any]) -> None:
    """JSON lines: a header object (``schema``, the run's summary, ``header``), then one per frame."""
    from knowledge.fileio import atomic_write_text

    lines = [json.dumps({"schema": TRACKS_SCHEMA, **header, "run": run.summary()}, sort_keys=True)]
    lines += [json.dumps(f.to_json(), separators=(",", ":")) for f in run.frames]
    atomic_write_text(path, "\n".join(lines) + "\n")


def read_tracks(path: Path) -> tuple[dict[str, Any], list[TrackFrame]]:
    """The header and frames of a tracks file written by :func:`write_tracks`.

    Raises:
        DataError: not such a file, or a line that does not parse (its number is named).
    """
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise DataError(f"{path}: cannot read the tracks file: {exc}") from exc
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise DataError(f"{path}: empty; write it with loci people track")
    try:
        header = json.loads(lines[0])
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}:1: not JSON: {exc}") from exc
    if not isinstance(header, dict) or header.get("schema") != TRACKS_SCHEMA:
        raise DataError(f"{path}:1: not a {TRACKS_SCHEMA} file (write it with loci people track)")
    frames = []
    for n, line in enumerate(lines[1:], start=2):
        try:
            frames.append(TrackFrame.from_json(json.loads(line)))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise DataError(f"{path}:{n}: not a track frame: {exc}") from exc
    stamps = [f.stamp for f in frames]
    if any(b <= a for a, b in itertools.pairwise(stamps)):
        raise DataError(f"{path}: the frames' stamps must increase")
    return header, frames


@dataclass(frozen=True, eq=False)
class Annotations:
    """The annotated people of a bag, by scan.

    Attributes:
        scan_stamps: ``(S,)`` header stamps of the bag's scans, in bag order, seconds.
        scan_times: ``(S,)`` their bag (log) times, seconds.
        stamp: ``(N,)`` the header stamp of the scan each annotation belongs to.
        ids: ``(N,)`` annotation ids; positions: ``(N, 2)`` metres in ``frame_id``.
        frame_id: the laser's frame (the annotation tool's fixed frame).
        before_first_scan: annotations written before the first scan (no scan to belong to).
    """

    scan_stamps: np.ndarray
    scan_times: np.ndarray
    stamp: np.ndarray
    ids: np.ndarray
    positions: np.ndarray
    frame_id: str
    before_first_scan: int = 0

    def __len__(self) -> int:
        return int(self.ids.size)

    def at(self, stamp: float) -> tuple[np.ndarray, np.ndarray]:
        """``(ids (G,), positions (G, 2))`` annotated on the scan with this stamp (to
        :data:`STAMP_TOLERANCE`: a stamp written and read again may lose its last digits)."""
        sel = np.abs(self.stamp - stamp) <= STAMP_TOLERANCE
        return self.ids[sel], self.positions[sel]


def read_annotations(
    path: str | Path, *, topic: str = ANNOTATION_TOPIC, scan_topic: str | None = None
) -> Annotations:
    """The annotations of a ROS 1 bag (see the module doc).

    Raises:
        DataError: the bag does not open, has no annotation topic of type ``leg_tracker/Person``,
            no (or several, without ``scan_topic``) LaserScan topics, or a message that does not
            deserialize (its number on the topic is named).
    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    src = Path(path)
    reader = _open_bag(src)
    try:
        conns = {c.topic: c for c in reader.connections}
        ann = conns.get(topic)
        if ann is None or ann.msgtype != PERSON_TYPE:
            have = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections if "Person" in c.msgtype)
            raise DataError(
                f"{src}: no {topic} topic of type {PERSON_TYPE}"
                + (f"; Person topics: {have}" if have else "")
            )
        scan_topic = _scan_topic(src, conns, scan_topic)
        store = get_typestore(Stores.ROS1_NOETIC)
        store.register(get_types_from_msg(ann.msgdef.data, ann.msgtype))
        scan_times, scan_stamps, frame_ids = [], [], set()
        rows: list[tuple[float, int, float, float]] = []
        counts = {scan_topic: 0, topic: 0}
        for conn, t, raw in reader.messages(connections=[conns[scan_topic], ann]):
            counts[conn.topic] += 1
            try:
                msg: Any = store.deserialize_ros1(raw, conn.msgtype)
            except Exception as exc:
                raise DataError(
                    f"{src}: message {counts[conn.topic]} on {conn.topic} does not deserialize: {exc}"
                ) from exc
            if conn.topic == scan_topic:
                scan_times.append(t * 1e-9)
                scan_stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
                frame_ids.add(msg.header.frame_id.lstrip("/"))
            else:
                p = msg.pose.position
                rows.append((t * 1e-9, int(msg.id), float(p.x), float(p.y)))
    finally:
        reader.close()
    st = np.asarray(scan_times, dtype=np.float64)
    sh = np.asarray(scan_stamps, dtype=np.float64)
    a = np.asarray(rows, dtype=np.float64).reshape(-1, 4)
    k = np.searchsorted(st, a[:, 0], side="left") - 1  # the scan before: strictly earlier in bag time
    keep = k >= 0
    return Annotations(
        scan_stamps=sh,
        scan_times=st,
        stamp=sh[k[keep]],
        ids=a[keep, 1].astype(np.int64),
        positions=a[keep, 2:4].copy(),
        frame_id=",".join(sorted(frame_ids)),
        before_first_scan=int((~keep).sum()),
    )


#: The benchmark's scorer counts only people between these bearings in the laser's frame
#: (degrees; its launch files for the "Moving" bags): both the annotations and the tracks.
BENCHMARK_ARC = (-80.0, 12.0)


@dataclass(frozen=True)
class TrackScores:
    """:func:`score_tracks`'s result: CLEAR-MOT, per-scan detections and what was scored."""

    mot: Any  # knowledge.people.clearmot.ClearMot
    detections: Any  # knowledge.people.clearmot.DetectionScores
    frames: int
    annotations: int
    annotations_outside_arc: int
    annotated_scans_missing: int
    window: tuple[float, float]

    def as_dict(self) -> dict[str, Any]:
        return {
            "clear_mot": self.mot.as_dict(),
            "detections": self.detections.as_dict(),
            "frames": self.frames,
            "annotations": self.annotations,
            "annotations_outside_arc": self.annotations_outside_arc,
            "annotated_scans_missing": self.annotated_scans_missing,
            "window_s": list(self.window),
        }


def score_tracks(
    frames: list[TrackFrame],
    truth: Annotations,
    *,
    arc_deg: tuple[float, float] | None = BENCHMARK_ARC,
    window: tuple[float, float] = (-math.inf, math.inf),
    threshold: float = 0.75,
    detection_distance: float = 0.5,
    coasting: bool = False,
) -> TrackScores:
    """Score tracks against annotations, frame by frame in the laser's frame at each scan.

    ``window``: seconds after the bag's first scan; only the frames whose stamp lies in
    ``[start, end)`` are scored (and the annotations of those scans). ``arc_deg``: only
    annotations and tracks between these bearings count (None: all). ``coasting``: also
    score confirmed tracks not seen in that scan (``misses > 0``); by default only the
    tracks seen in the scan count, as the benchmark's trackers published them.

    Raises:
        DataError: no frame in the window.
    """
    from knowledge.people.clearmot import MotFrame, clear_mot, detection_scores

    t0 = float(truth.scan_stamps[0]) if truth.scan_stamps.size else 0.0
    lo, hi = (
        (math.radians(arc_deg[0]), math.radians(arc_deg[1])) if arc_deg is not None else (-math.pi, math.pi)
    )

    def inside(p: np.ndarray) -> np.ndarray:
        a = np.arctan2(p[:, 1], p[:, 0])
        return (a >= lo) & (a <= hi)

    by_stamp = {f.stamp: f for f in frames if window[0] <= f.stamp - t0 < window[1]}
    known = np.array(sorted(by_stamp))
    annotated = set()
    for v in np.unique(truth.stamp):
        if window[0] <= float(v) - t0 < window[1]:
            k = int(np.argmin(np.abs(known - v))) if known.size else -1
            near = k >= 0 and abs(known[k] - v) <= STAMP_TOLERANCE
            annotated.add(float(known[k]) if near else float(v))
    if not by_stamp:
        raise DataError(f"no tracked scan in the window {window[0]:g}-{window[1]:g} s after the first scan")
    mot_frames, det_frames = [], []
    outside = n_ann = 0
    empty = np.zeros((0, 2))
    for stamp in sorted(set(by_stamp) | annotated):
        ids, pos = truth.at(stamp)
        keep = inside(pos)
        n_ann += int(ids.size)
        outside += int((~keep).sum())
        ids, pos = ids[keep], pos[keep]
        f = by_stamp.get(stamp)
        if f is None:  # an annotated scan the tracker never got (dropped): its people are missed
            mot_frames.append(MotFrame(ids, pos, np.zeros(0, dtype=np.int64), empty, stamp))
            det_frames.append((pos, empty))
            continue
        tr = f.tracks if coasting else f.tracks[f.tracks[:, 3] == 0]
        est = f.in_sensor_frame(tr[:, 1:3])
        sel = inside(est)
        mot_frames.append(MotFrame(ids, pos, tr[sel, 0].astype(np.int64), est[sel], stamp))
        people = f.in_sensor_frame(f.people)
        det_frames.append((pos, people[inside(people)]))
    return TrackScores(
        mot=clear_mot(mot_frames, threshold),
        detections=detection_scores(det_frames, detection_distance),
        frames=len(mot_frames),
        annotations=n_ann,
        annotations_outside_arc=outside,
        annotated_scans_missing=len(annotated - set(by_stamp)),
        window=window,
    )


def read_bag_scans(path: str | Path, *, scan_topic: str | None = None) -> list[Any]:
    """The LaserScans of a ROS 1 bag as :class:`~drivers.messages.LaserScan` (REP 117 ranges
    converted as ``loci import`` does), in bag order.

    Raises:
        DataError: the bag does not open, the scan topic is ambiguous or missing, or a scan
            does not deserialize or has impossible values (its number is named).
    """
    from rosbags.typesys import Stores, get_typestore

    from agent.recording.rosbag import BadMessage, scan_from_ros

    src = Path(path)
    reader = _open_bag(src)
    try:
        conns = {c.topic: c for c in reader.connections}
        scan_topic = _scan_topic(src, conns, scan_topic)
        store = get_typestore(Stores.ROS1_NOETIC)
        out = []
        for n, (conn, _, raw) in enumerate(reader.messages(connections=[conns[scan_topic]]), start=1):
            try:
                out.append(scan_from_ros(store.deserialize_ros1(raw, conn.msgtype), n))
            except BadMessage as exc:
                raise DataError(f"{src}: scan {n} on {scan_topic}: {exc}") from exc
            except Exception as exc:
                raise DataError(f"{src}: scan {n} on {scan_topic} does not deserialize: {exc}") from exc
    finally:
        reader.close()
    return out


def bag_examples(
    path: str | Path,
    *,
    window: tuple[float, float] = (-math.inf, math.inf),
    arc_deg: tuple[float, float] | None = BENCHMARK_ARC,
    jump: float = 0.15,
    max_gap: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, int]]:
    """Labelled segments of an annotated benchmark bag for training the leg detector:
    ``(X (n, 14), y (n,) bool, distance (n,), counts)``, from the scans ``window`` seconds
    after its first scan (:func:`knowledge.people.dataset.label_person_annotations`: legs
    near an annotated person are people, segments in the arc far from everyone are not).
    """
    X, y, dist, t, scans = bag_segments(path, arc_deg=arc_deg, jump=jump, max_gap=max_gap)
    keep = (window[0] <= t) & (t < window[1])
    used = int(((window[0] <= scans) & (scans < window[1])).sum())
    if not used:
        raise DataError(f"{path}: no scan in the window {window[0]:g}-{window[1]:g} s after the first scan")
    X, y, dist = X[keep], y[keep], dist[keep]
    return X, y, dist, {"scans": used, "people": int(y.sum()), "non_people": int((~y).sum())}


def bag_segments(
    path: str | Path,
    *,
    arc_deg: tuple[float, float] | None = BENCHMARK_ARC,
    jump: float = 0.15,
    max_gap: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every labelled segment of an annotated bag (see :func:`bag_examples`) with its time:
    ``(X (n, 14), y (n,) bool, distance (n,), t (n,), scan_t (S,))``, ``t`` and ``scan_t`` the
    seconds after the bag's first scan of each segment's scan and of every scan (so that
    parts split by time are cut from one read of the bag)."""
    from knowledge.people.dataset import POSITIVE, label_person_annotations
    from knowledge.people.features import _features
    from knowledge.people.segmentation import segment_scan

    truth = read_annotations(path)
    scans = read_bag_scans(path)
    t0 = float(truth.scan_stamps[0]) if truth.scan_stamps.size else 0.0
    Xs, ys, ds, ts = [], [], [], []
    for scan in scans:
        seg = segment_scan(
            scan.ranges,
            scan.angle_min,
            scan.angle_increment,
            range_max=scan.range_max,
            range_min=scan.range_min,
            jump=jump,
            max_gap=max_gap,
        )
        X, centre = _features(seg, range_max=scan.range_max, range_min=scan.range_min)
        _, people = truth.at(scan.stamp)
        labels = label_person_annotations(X, centre, people, arc_deg=arc_deg)
        keep = labels >= 0
        Xs.append(X[keep])
        ys.append(labels[keep] == POSITIVE)
        ds.append(np.hypot(centre[keep, 0], centre[keep, 1]))
        ts.append(np.full(int(keep.sum()), scan.stamp - t0))
    if not Xs:
        raise DataError(f"{path}: no scans")
    scan_t = np.array([s.stamp - t0 for s in scans], dtype=np.float64)
    return np.concatenate(Xs), np.concatenate(ys), np.concatenate(ds), np.concatenate(ts), scan_t


def _scan_topic(src: Path, conns: dict[str, Any], wanted: str | None) -> str:
    """The bag's LaserScan topic: ``wanted`` if it is one, else the only one (DataError naming
    the choices otherwise)."""
    scans = sorted(t for t, c in conns.items() if c.msgtype == "sensor_msgs/msg/LaserScan")
    if wanted is None:
        if len(scans) != 1:
            raise DataError(f"{src}: choose the scan topic (LaserScan topics: {', '.join(scans) or 'none'})")
        return scans[0]
    if wanted not in scans:
        raise DataError(f"{src}: {wanted} is not a LaserScan topic (those: {', '.join(scans) or 'none'})")
    return wanted


def _open_bag(src: Path) -> Any:
    """A rosbags ROS 1 reader, open; DataError when the file cannot be read as a bag."""
    from rosbags.rosbag1 import Reader

    try:
        reader = Reader(src)
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, and OSError, on damage
        raise DataError(f"{src}: cannot open as a ROS 1 bag: {exc}") from exc
    return reader
