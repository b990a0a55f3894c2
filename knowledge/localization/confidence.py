"""How sure the tracked pose is: the state a robot tells people and acts on.

:class:`ConfidenceTracker` follows the tracker's steps (:class:`~knowledge.localization.tracking.TrackStep`)
and says, after each, how far the pose may be off and whether the robot should trust it:

* ``tracking``: the scan matched the map well and no recent correction waits for the next
  scans' verdict; the pose is as good as the matcher (``σ`` = the noise model's floor);
* ``uncertain``: a correction larger than the odometry's noise model allows was just taken
  (its deviation becomes ``σ``), or scans fit poorly or did not match, so the pose rests on
  odometry alone: ``σ`` grows with each such scan by the noise model of its increment (root
  sum of squares);
* ``lost``: uncertain for ``lost_after`` scans in a row.

A robot that is not ``tracking`` says "I think I have reached …" rather than "I have reached
…" (:mod:`agent.conversation`). Everything here follows from the steps alone: a replay says
what the live run said.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from knowledge.localization.tracking import TrackStep

__all__ = ["STATES", "Confidence", "ConfidenceTracker"]

#: The states, from sure to lost.
STATES = ("tracking", "uncertain", "lost")


@dataclass(frozen=True)
class Confidence:
    """How sure the pose is after a scan.

    Attributes:
        state: one of :data:`STATES`.
        sigma: ``(metres, radians)`` how far the pose may be off (one standard deviation).
        fit: the scan's match fit (0 when it did not match).
        event: the tracker's event of this scan (a correction, an undone one, a stall), or None.
        deviation: ``(metres, radians)`` the pose taken from the odometry's prediction.
        scans: scans in this state in a row (this one included).
    """

    state: str
    sigma: tuple[float, float]
    fit: float
    event: str | None = None
    deviation: tuple[float, float] = (0.0, 0.0)
    scans: int = 1

    @property
    def certain(self) -> bool:
        return self.state == "tracking"

    def as_dict(self) -> dict[str, object]:
        return {
            "state": self.state,
            "sigma": round(self.sigma[0], 4),
            "sigma_theta": round(self.sigma[1], 4),
            "fit": round(self.fit, 4),
            "event": self.event,
            "deviation": round(self.deviation[0], 4),
            "deviation_theta": round(self.deviation[1], 4),
        }


class ConfidenceTracker:
    """Follows the tracker's steps (see the module docstring).

    Args:
        floor: ``(metres, radians)``, ``σ`` while tracking (the tracker's ``noise_floor``).
        lost_after: uncertain scans in a row after which the robot counts as lost.
    """

    def __init__(self, floor: tuple[float, float] = (0.03, 0.03), *, lost_after: int = 75) -> None:
        if lost_after < 1:
            raise ValueError(f"lost_after must be >= 1 scan, got {lost_after}")
        self.floor = (float(floor[0]), float(floor[1]))
        self.lost_after = lost_after
        self.current: Confidence | None = None

    def update(self, step: TrackStep) -> Confidence:
        """The confidence after ``step``."""
        prev = self.current
        if not step.uncertain:
            state, sigma = "tracking", self.floor
        else:
            base = self.floor if prev is None or prev.state == "tracking" else prev.sigma
            s_t = math.hypot(base[0], step.sigma[0])
            s_r = math.hypot(base[1], step.sigma[1])
            if step.event == "correction":
                s_t, s_r = max(s_t, step.deviation[0]), max(s_r, step.deviation[1])
            run = 1 if prev is None or prev.state == "tracking" else prev.scans + 1
            state = "lost" if run >= self.lost_after else "uncertain"
            sigma = (s_t, s_r)
        scans = prev.scans + 1 if prev is not None and prev.state == state else 1
        if state != "tracking" and prev is not None and prev.state != "tracking":
            scans = prev.scans + 1  # uncertain and lost count as one run
        self.current = Confidence(state, sigma, step.fit, step.event, step.deviation, scans)
        return self.current
