"""How sure the tracked pose is (knowledge.localization.confidence)."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.localization.confidence import ConfidenceTracker
from knowledge.localization.tracking import TrackStep


def step(
    uncertain: bool = False, event: str | None = None, deviation: float = 0.0, sigma: float = 0.04
) -> TrackStep:
    z = np.zeros(3)
    return TrackStep(z, z, 0.9, True, False, False, (deviation, 0.0), (sigma, 0.03), uncertain, event)


def test_states_and_sigma() -> None:
    c = ConfidenceTracker((0.03, 0.02), lost_after=4)
    assert c.update(step()).state == "tracking" and c.current is not None and c.current.sigma == (0.03, 0.02)
    # a correction the odometry cannot explain: uncertain, sigma at least the correction
    got = c.update(step(True, "correction", deviation=0.4))
    assert got.state == "uncertain" and got.sigma[0] == pytest.approx(0.4) and not got.certain
    # uncertain scans after it: sigma grows by the noise model of each increment
    s1 = c.update(step(True)).sigma[0]
    assert s1 == pytest.approx(np.hypot(0.4, 0.04))
    assert c.update(step(True)).state == "uncertain"
    assert c.update(step(True)).state == "lost"  # 4 uncertain scans in a row
    back = c.update(step())
    assert back.state == "tracking" and back.certain and back.sigma == (0.03, 0.02) and back.scans == 1
    assert back.as_dict()["state"] == "tracking"
    with pytest.raises(ValueError, match="lost_after"):
        ConfidenceTracker(lost_after=0)
