"""The odometry motion model of a differential-drive robot (Thrun, Burgard, Fox,
*Probabilistic Robotics*, Table 5.6, ``sample_motion_model_odometry``).

The motion between two odometry poses is taken apart into a turn ``δrot1`` towards where the
robot went, a straight ``δtrans`` and a second turn ``δrot2``; each is perturbed by Gaussian
noise whose variance grows with the motion — ``α1·δrot² + α2·δtrans²`` for the turns,
``α3·δtrans² + α4·(δrot1² + δrot2²)`` for the straight part — and the perturbed motion is
applied to every particle in its own frame. A robot driving backwards turns by about π in
``δrot1``; as AMCL does, the turns' noise then uses the smaller angle ``π − |δrot1|``.
Motions under 1 cm have no ``δrot1`` (its direction would be noise).

Poses are ``(x, y, theta)``: metres and radians; the α are dimensionless (rad²/rad²,
rad²/m², m²/m², m²/rad²).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from knowledge.localization.se2 import wrap

__all__ = ["MotionNoise", "odometry_increment", "sample_motion"]


@dataclass(frozen=True)
class MotionNoise:
    """The α of the odometry motion model (see the module docstring).

    Attributes:
        rot_rot: α1, turn noise from turning.
        rot_trans: α2, turn noise from driving.
        trans_trans: α3, distance noise from driving.
        trans_rot: α4, distance noise from turning.
    """

    rot_rot: float = 0.2
    rot_trans: float = 0.05
    trans_trans: float = 0.1
    trans_rot: float = 0.01

    def __post_init__(self) -> None:
        for name in ("rot_rot", "rot_trans", "trans_trans", "trans_rot"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"MotionNoise.{name} must be >= 0, got {v!r}")


def odometry_increment(previous: npt.ArrayLike, current: npt.ArrayLike) -> tuple[float, float, float]:
    """``(δrot1, δtrans, δrot2)`` of the motion from ``previous`` to ``current``."""
    p = np.asarray(previous, dtype=np.float64)
    c = np.asarray(current, dtype=np.float64)
    dx, dy = float(c[0] - p[0]), float(c[1] - p[1])
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < 0.01 else float(wrap(math.atan2(dy, dx) - p[2]))
    rot2 = float(wrap(c[2] - p[2] - rot1))
    return rot1, trans, rot2


def sample_motion(
    particles: np.ndarray,
    previous: npt.ArrayLike,
    current: npt.ArrayLike,
    noise: MotionNoise,
    rng: np.random.Generator,
) -> np.ndarray:
    """``(N, 3)`` the particles moved by the odometry motion from ``previous`` to ``current``
    with sampled noise (a new array)."""
    rot1, trans, rot2 = odometry_increment(previous, current)
    n = particles.shape[0]
    r1 = min(abs(rot1), abs(math.pi - abs(rot1)))
    r2 = min(abs(rot2), abs(math.pi - abs(rot2)))
    a1, a2, a3, a4 = noise.rot_rot, noise.rot_trans, noise.trans_trans, noise.trans_rot
    s_rot1 = math.sqrt(a1 * r1 * r1 + a2 * trans * trans)
    s_trans = math.sqrt(a3 * trans * trans + a4 * (r1 * r1 + r2 * r2))
    s_rot2 = math.sqrt(a1 * r2 * r2 + a2 * trans * trans)
    h1 = rot1 - rng.normal(0.0, 1.0, n) * s_rot1 if s_rot1 > 0 else np.full(n, rot1)
    t = trans - rng.normal(0.0, 1.0, n) * s_trans if s_trans > 0 else np.full(n, trans)
    h2 = rot2 - rng.normal(0.0, 1.0, n) * s_rot2 if s_rot2 > 0 else np.full(n, rot2)
    th = particles[:, 2] + h1
    out = np.empty_like(particles)
    out[:, 0] = particles[:, 0] + t * np.cos(th)
    out[:, 1] = particles[:, 1] + t * np.sin(th)
    out[:, 2] = wrap(th + h2)
    return out
