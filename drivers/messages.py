"""Typed sensor messages shared by the drivers, the simulator and the Zenoh/MCAP codecs.

Small frozen dataclasses with units in their docstrings. Arrays inside them are made
read-only so a message can be handed to several consumers without copies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _readonly(a: np.ndarray | None, dtype: type[np.generic]) -> np.ndarray | None:
    if a is None:
        return None
    with np.errstate(over="ignore"):  # doubles beyond float32's range become ±inf, no warning
        arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class LaserScan:
    """One planar laser scan.

    Attributes:
        stamp: acquisition time of the first beam, seconds since the Unix epoch.
        seq: sequence number from the source (monotonic per device, wraps are the source's business).
        frame_id: the sensor's frame name (e.g. ``"laser"``).
        angle_min: angle of the first beam relative to the sensor's x axis, radians (counter-clockwise).
        angle_increment: angle between consecutive beams, radians (> 0).
        range_max: the sensor's maximum range in metres; beams that hit nothing carry this value.
        ranges: ``(n,)`` float32 ranges in metres.
        intensities: ``(n,)`` float32 reflectivity values when the sensor reports them, else None.
        range_min: readings below this (metres) are invalid (e.g. dazzle, too close).
        scan_time: seconds between two scans of the source (0 if unknown).
    """

    stamp: float
    seq: int
    frame_id: str
    angle_min: float
    angle_increment: float
    range_max: float
    ranges: np.ndarray
    intensities: np.ndarray | None = None
    range_min: float = 0.0
    scan_time: float = 0.0

    def __post_init__(self) -> None:
        ranges = _readonly(self.ranges, np.float32)
        assert ranges is not None
        if ranges.ndim != 1 or ranges.size == 0:
            raise ValueError(f"LaserScan.ranges must be a non-empty 1-D array, got shape {ranges.shape}")
        if not (self.angle_increment > 0 and math.isfinite(self.angle_increment)):
            raise ValueError(f"LaserScan.angle_increment must be > 0 radians, got {self.angle_increment}")
        if not (self.range_max > 0 and math.isfinite(self.range_max)):
            raise ValueError(f"LaserScan.range_max must be > 0 metres, got {self.range_max}")
        intens = _readonly(self.intensities, np.float32)
        if intens is not None and intens.shape != ranges.shape:
            raise ValueError(f"LaserScan.intensities {intens.shape} must match ranges {ranges.shape}")
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "intensities", intens)

    @property
    def n_beams(self) -> int:
        return int(self.ranges.shape[0])

    @property
    def angle_max(self) -> float:
        """Angle of the last beam, radians."""
        return self.angle_min + (self.n_beams - 1) * self.angle_increment

    @property
    def angles(self) -> np.ndarray:
        """``(n,)`` float64 beam angles in radians."""
        return self.angle_min + np.arange(self.n_beams) * self.angle_increment


@dataclass(frozen=True)
class Pose2D:
    """A planar pose (odometry or a goal).

    Attributes:
        x, y: position in metres in ``frame_id``.
        theta: heading in radians (counter-clockwise from x), normalised to (-π, π].
        stamp: seconds since the Unix epoch.
        frame_id: the frame the pose is expressed in (``"odom"`` for odometry).
    """

    x: float
    y: float
    theta: float
    stamp: float = 0.0
    frame_id: str = "odom"

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x, self.y, self.theta)):
            raise ValueError(f"Pose2D needs finite x, y, theta, got {(self.x, self.y, self.theta)}")
        object.__setattr__(self, "theta", math.atan2(math.sin(self.theta), math.cos(self.theta)))

    def as_array(self) -> np.ndarray:
        """``(3,)`` float64 ``[x, y, theta]``."""
        return np.array([self.x, self.y, self.theta])


@dataclass(frozen=True)
class Twist2D:
    """A velocity command or measurement: ``v`` forward m/s, ``omega`` counter-clockwise rad/s."""

    v: float
    omega: float
    stamp: float = 0.0


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One camera image.

    Attributes:
        stamp: capture time, seconds since the Unix epoch.
        seq: frame counter of the source.
        frame_id: the camera's frame name.
        image: ``(h, w, 3)`` uint8 BGR (OpenCV's order), or None when only ``jpeg`` is carried.
        jpeg: JPEG-compressed bytes (for publishing), or None.
    """

    stamp: float
    seq: int
    frame_id: str
    image: np.ndarray | None = None
    jpeg: bytes | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.image is None and self.jpeg is None:
            raise ValueError("CameraFrame needs an image or JPEG bytes")
        if self.image is not None:
            img = np.asarray(self.image)
            if img.dtype != np.uint8 or img.ndim not in (2, 3):
                raise ValueError(f"CameraFrame.image must be uint8 (h, w[, 3]), got {img.dtype} {img.shape}")
            img = np.array(img, copy=True)
            img.setflags(write=False)
            object.__setattr__(self, "image", img)
