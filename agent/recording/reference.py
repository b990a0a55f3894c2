"""Reference poses from a corrected copy of a log, added to the raw log's recording.

``loci import RAW.log.gz raw.mcap --reference CORRECTED.log.gz`` imports the raw log as
usual, then (:func:`add_reference`) reads the corrected log — a CARMEN log whose laser lines
carry the corrected poses (imported with ``--truth laser``), or a recording with
``pose/truth`` — matches its scans to the raw ones by their ranges
(:func:`knowledge.localization.reference.match_scans`) and writes each matched scan's
corrected pose on ``loci/<robot>/pose/truth`` (frame ``map``), stamped with the **raw** scan's
stamp and logged right after it. The raw odometry stays on ``odom``: raw odometry in,
corrected poses as the truth (the localization evaluation, docs/localization.md).
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agent.bus.bridge import RawSample
from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC, checked_decode
from agent.bus.keys import stream_key
from agent.recording.recorder import McapSink
from agent.recording.replay import McapMessages
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import DataError, ProtocolError
from knowledge.fileio import file_sha256
from knowledge.localization.reference import match_scans

__all__ = ["ReferenceResult", "add_reference", "reference_scans"]


@dataclass
class ReferenceResult:
    """What :func:`add_reference` did: reference scans read, matched, and written poses."""

    reference: Path
    reference_scans: int
    matched: int
    raw_scans: int

    def summary(self) -> str:
        return (
            f"reference {self.reference.name}: {self.matched} of its {self.reference_scans} scans matched "
            f"to the {self.raw_scans} scans by their ranges; {self.matched} reference poses on pose/truth"
        )


def _robot_of(path: Path) -> str:
    from agent.recording.offline import read_recording_metadata

    robot = read_recording_metadata(path).get("robot")
    if not robot:
        raise DataError(f"{path}: the recording does not name its robot (no loci metadata)")
    return robot


def _is_mcap(path: Path) -> bool:
    from agent.recording.importer import MCAP_MAGIC

    try:
        with path.open("rb") as f:
            return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError as exc:
        raise DataError(f"{path}: cannot read the reference ({exc.strerror})") from exc


def reference_scans(path: Path) -> list[tuple[LaserScan, Pose2D]]:
    """The scans of a recording that have a reference pose of the same stamp, with that pose."""
    robot = _robot_of(path)
    scan_key, truth_key = stream_key(robot, "scan"), stream_key(robot, "pose/truth")
    scans: dict[float, LaserScan] = {}
    poses: dict[float, Pose2D] = {}
    for msg in McapMessages(path, topics={scan_key, truth_key}):
        if msg.topic == scan_key:
            scan = checked_decode(LASER_SCAN_CODEC, msg.zenoh_encoding, msg.data, msg.topic)
            scans.setdefault(scan.stamp, scan)
        else:
            pose = checked_decode(POSE_CODEC, msg.zenoh_encoding, msg.data, msg.topic)
            poses.setdefault(pose.stamp, pose)
    out = [(scans[t], poses[t]) for t in sorted(scans) if t in poses]
    if not out:
        raise DataError(
            f"{path}: no scan has a reference pose of its stamp on {truth_key} "
            "(import a corrected CARMEN log with --truth laser)"
        )
    return out


def add_reference(
    recording: Path, reference: Path, output: Path, *, overwrite: bool = False
) -> ReferenceResult:
    """Write ``output``: ``recording`` with the reference poses of ``reference`` (see the module
    docstring). ``reference`` is a CARMEN log or an MCAP recording with ``pose/truth``.

    Raises:
        DataError: unreadable files, or no reference scan matched.
    """
    from agent.recording.carmen import CarmenOptions
    from agent.recording.importer import detect_format, import_log
    from agent.recording.offline import read_recording_metadata

    if output.exists() and not overwrite:
        raise DataError(f"{output} exists; choose another name or allow overwriting (--force)")
    with tempfile.TemporaryDirectory(prefix="loci-reference-") as tmp:
        ref_rec = reference
        if not _is_mcap(reference):
            if detect_format(reference) != "carmen":
                raise DataError(
                    f"{reference}: a reference must be a corrected CARMEN log or a recording with pose/truth"
                )
            ref_rec = Path(tmp) / "reference.mcap"
            import_log(reference, ref_rec, carmen=CarmenOptions(truth="laser"), emit=lambda s: None)
        refs = reference_scans(ref_rec)
    meta = read_recording_metadata(recording)
    robot = meta.get("robot") or _robot_of(recording)
    scan_key, truth_key = stream_key(robot, "scan"), stream_key(robot, "pose/truth")
    raw: list[np.ndarray] = []
    for msg in McapMessages(recording, topics={scan_key}):
        try:
            raw.append(checked_decode(LASER_SCAN_CODEC, msg.zenoh_encoding, msg.data, msg.topic).ranges)
        except ProtocolError:  # a scan that does not decode matches nothing (and is replayed as invalid)
            raw.append(np.full(1, np.nan, dtype=np.float32))
    pairs = match_scans(raw, [s.ranges for s, _ in refs])
    if not pairs:
        raise DataError(f"{reference}: none of its {len(refs)} scans equals a scan of {recording}")
    truth_of = {i: refs[j][1] for i, j in pairs}
    meta = {
        **{k: v for k, v in meta.items() if k != "created"},
        "reference": str(reference.resolve()),
        "reference_sha256": file_sha256(reference) if reference.is_file() else "",
        "reference_matched": json.dumps({"matched": len(pairs), "reference_scans": len(refs)}),
    }
    partial = output.with_name(output.name + ".partial")
    try:
        with McapSink(partial, overwrite=True, metadata=meta) as sink:
            index = -1
            for msg in McapMessages(recording):
                sample = RawSample(
                    msg.topic, msg.data, msg.zenoh_encoding, msg.log_time_ns, msg.publish_time_ns
                )
                sink.write(sample)
                if msg.topic != scan_key:
                    continue
                index += 1
                pose = truth_of.get(index)
                if pose is not None:
                    scan = checked_decode(LASER_SCAN_CODEC, msg.zenoh_encoding, msg.data, msg.topic)
                    truth = Pose2D(pose.x, pose.y, pose.theta, stamp=scan.stamp, frame_id="map")
                    sink.write(
                        RawSample(
                            truth_key, POSE_CODEC.encode(truth), POSE_CODEC.zenoh_encoding, msg.log_time_ns
                        )
                    )
        partial.replace(output)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    return ReferenceResult(reference, len(refs), len(pairs), len(raw))
