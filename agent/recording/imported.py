"""What the log importers produce, and how they count: shared by :mod:`agent.recording.carmen`,
:mod:`agent.recording.rosbag` and the writer :mod:`agent.recording.importer`.

Pure code. A converter turns each message of a log (a CARMEN line, a bag message) into
:class:`Output` s (a scan, an odometry pose or a reference pose, with the time it was logged)
or a :class:`Skip` naming why it was left out. :class:`ImportStats` keeps the books so that

    messages read = messages imported + messages skipped (by reason)

holds, and :class:`Warnings` says what was wrong with the input, naming the line or message
number: the first few of each reason, then a count. Reasons in :data:`BAD_INPUT` are bad
input (a truncated file or line, an unknown line type, a scan with NaN ranges, ...): with
``strict`` the first one is an error (:class:`~knowledge.errors.DataError`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.messages import LaserScan, Pose2D
from knowledge.errors import DataError

#: The streams an import writes (suffixes of ``loci/<robot>/``; see ``agent/bus/keys.py``).
SCAN, ODOM, TRUTH = "scan", "odom", "pose/truth"

#: Reasons that mean the input is damaged or not what it claims: warned, and with
#: ``--strict`` the first one stops the import.
BAD_INPUT = frozenset(
    {
        "truncated_file",  # the file (or its gzip stream) ends early
        "corrupt_file",  # gzip CRC error, unreadable bag chunk
        "truncated_line",  # a line with fewer fields than its type needs (cut in the middle)
        "bad_line",  # a field that is not a number, counts that do not add up
        "unknown_type",  # a CARMEN line type the importer does not know
        "zero_beams",  # a laser message without beams
        "no_time",  # a message whose times are 0 (or negative)
        "time_backwards",  # logged before the message before it
        "bad_ranges",  # NaN or negative ranges (the scan is kept, those beams made invalid)
        "stamp_not_increasing",  # a scan or odometry stamp not after the previous one (kept)
        "corrupt_message",  # a bag message that does not deserialize
        "bad_message",  # a bag message with impossible values (zero angle increment, ...)
        "mount_changed",  # the laser's mount on the base moves in /tf (the first one is used)
        "no_mount",  # /tf does not connect the base and the laser
        "unknown_message_type",  # a needed bag topic whose type has no definition anywhere
    }
)


@dataclass(frozen=True)
class Output:
    """One message to write.

    Attributes:
        stream: :data:`SCAN`, :data:`ODOM` or :data:`TRUTH`.
        message: a :class:`LaserScan` (scan) or a :class:`Pose2D` (odom, truth).
        log_time: when it was logged (received), seconds: the MCAP log time.
    """

    stream: str
    message: LaserScan | Pose2D
    log_time: float


@dataclass(frozen=True)
class Skip:
    """A message left out, and why (``detail`` goes into the warning of a bad-input reason)."""

    reason: str
    detail: str = ""


Outcome = list[Output] | Skip


class Warnings:
    """Rate-limited warnings: the first ``limit`` of each reason are emitted, then only counted.

    Args:
        emit: where a warning's text goes (e.g. ``logging.warning``).
        limit: warnings emitted per reason.
        strict: raise :class:`DataError` on the first warning instead.
    """

    def __init__(self, emit: Callable[[str], None], *, limit: int = 3, strict: bool = False) -> None:
        self.emit = emit
        self.limit = limit
        self.strict = strict
        self.counts: Counter[str] = Counter()

    def __call__(self, reason: str, text: str) -> None:
        self.counts[reason] += 1
        if self.strict:
            raise DataError(f"{text} [{reason}; --strict stops at the first bad input]")
        if self.counts[reason] <= self.limit:
            self.emit(f"{text} [{reason}]")

    def finish(self) -> None:
        """Emit how many warnings of each reason were not shown."""
        for reason, n in sorted(self.counts.items()):
            if n > self.limit:
                self.emit(f"... and {n - self.limit} more {reason} warnings like these")


@dataclass
class ImportStats:
    """The books of one import.

    Attributes:
        read: messages read (CARMEN: non-empty lines; bags: messages).
        imported: messages that gave at least one output.
        skipped: reason → messages left out.
        written: stream → messages written.
        notes: reason → messages imported with something wrong that was repaired or kept
            (NaN ranges made invalid, a stamp not after the previous one).
        beams: beam counters (``sick_no_return``, ``sick_invalid``, ``no_return``, ``invalid``).
        file_errors: reason → damage to the file itself (truncated, corrupt), not a message.
        unknown_types: CARMEN line type → lines (what ``unknown_type`` skipped).
    """

    read: int = 0
    imported: int = 0
    skipped: Counter[str] = field(default_factory=Counter)
    written: Counter[str] = field(default_factory=Counter)
    notes: Counter[str] = field(default_factory=Counter)
    beams: Counter[str] = field(default_factory=Counter)
    file_errors: Counter[str] = field(default_factory=Counter)
    unknown_types: Counter[str] = field(default_factory=Counter)

    def add(self, outcome: Outcome) -> None:
        self.read += 1
        if isinstance(outcome, Skip):
            self.skipped[outcome.reason] += 1
            return
        self.imported += 1
        for out in outcome:
            self.written[out.stream] += 1

    @property
    def balanced(self) -> bool:
        """``read == imported + sum(skipped)``."""
        return self.read == self.imported + sum(self.skipped.values())

    def as_dict(self) -> dict[str, Any]:
        return {
            "read": self.read,
            "imported": self.imported,
            "skipped": dict(sorted(self.skipped.items())),
            "written": dict(sorted(self.written.items())),
            "notes": dict(sorted(self.notes.items())),
            "beams": dict(sorted(self.beams.items())),
            "file_errors": dict(sorted(self.file_errors.items())),
            "unknown_types": dict(sorted(self.unknown_types.items())),
        }

    def summary(self, unit: str = "messages") -> str:
        """One line that adds up: read = imported + skipped by reason."""
        skipped = sum(self.skipped.values())
        w = self.written
        parts = [
            f"{self.read:,} {unit} read = {self.imported:,} imported "
            f"({w[SCAN]:,} scans, {w[ODOM]:,} odometry, {w[TRUTH]:,} reference poses)"
            f" + {skipped:,} skipped"
        ]
        if skipped:
            reasons = []
            for reason, n in self.skipped.most_common():
                what = reason
                if reason == "unknown_type" and self.unknown_types:
                    what += " (" + ", ".join(f"{t} {c:,}" for t, c in self.unknown_types.most_common()) + ")"
                reasons.append(f"{n:,} {what}")
            parts[0] += " (" + ", ".join(reasons) + ")"
        if self.notes:
            parts.append(
                "kept with a warning: " + ", ".join(f"{n:,} {r}" for r, n in self.notes.most_common())
            )
        if self.file_errors:
            parts.append("file: " + ", ".join(f"{r}" for r in sorted(self.file_errors)))
        return "; ".join(parts)


# ---- planar poses --------------------------------------------------------------------


def compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """``a ∘ b``: pose ``b`` given in the frame of pose ``a``, expressed in ``a``'s parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2]))


def inverse(a: tuple[float, float, float]) -> tuple[float, float, float]:
    """The pose ``a⁻¹`` with ``a ∘ a⁻¹`` = identity."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], _wrap(-a[2]))


def _wrap(theta: float) -> float:
    return math.atan2(math.sin(theta), math.cos(theta))


def same_pose(a: tuple[float, float, float], b: tuple[float, float, float], tol: float = 1e-3) -> bool:
    """Within ``tol`` metres and ``tol`` radians."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) <= tol and abs(_wrap(a[2] - b[2])) <= tol
