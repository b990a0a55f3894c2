"""Measuring localization on a log with reference poses: convergence of global localization
and recovery of a kidnapped robot.

A run feeds a :class:`~knowledge.localization.mcl.ParticleFilter` the scans of a log from
scan ``start`` on and compares its estimate with the reference pose at every scan that has
one. It **converges** at the first reference scan from which the estimate's position error
stays below ``threshold`` (0.5 m) until the run's end; the **distance** it needed is the
path the odometry drove from the start to that scan (odometry is good over tens of metres,
and the reference poses are sparser than the scans). Runs end after ``max_distance`` metres
of driving or at the log's end; a run that never stays below the threshold has not
converged.

Everything takes arrays: ``odom`` ``(n, 3)`` laser odometry poses, ``ranges`` ``(n, B)``,
``angles`` ``(B,)``, ``proba`` ``(n, K)`` the classifier's histograms (or None), ``pairs``
``(m, 2)`` (scan index, reference index) and ``truth`` ``(M, 3)`` the laser's reference poses.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from knowledge.localization.mcl import ParticleFilter

__all__ = ["GlobalRun", "convergence", "odometry_distance", "run_filter"]


def odometry_distance(odom: npt.ArrayLike) -> np.ndarray:
    """``(n,)`` metres driven from the first pose to each (the sum of the steps)."""
    o = np.asarray(odom, dtype=np.float64)
    steps = np.hypot(np.diff(o[:, 0]), np.diff(o[:, 1]))
    return np.concatenate([[0.0], np.cumsum(steps)])


def convergence(errors: npt.ArrayLike, threshold: float = 0.5) -> int | None:
    """The first index from which every error is below ``threshold`` (None: never)."""
    e = np.asarray(errors, dtype=np.float64)
    if e.size == 0 or not e[-1] < threshold:
        return None
    bad = np.nonzero(~(e < threshold))[0]
    return 0 if bad.size == 0 else int(bad[-1]) + 1


@dataclass
class GlobalRun:
    """One run of a filter over a stretch of a log.

    Attributes:
        start: the first scan.
        converged: the estimate stayed within the threshold to the end.
        distance: metres driven until it converged (nan: never).
        errors: position errors at the reference scans; ``at``: their scan indices;
            ``driven``: metres driven to each.
        final_error: the last error (metres).
        updates: measurement updates; seconds: time spent in the filter.
        snapshots: scan index → ``(N, 3)`` world particles, for pictures.
    """

    start: int
    converged: bool
    distance: float
    errors: np.ndarray
    at: np.ndarray
    driven: np.ndarray
    final_error: float
    updates: int
    seconds: float
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)


def run_filter(
    pf: ParticleFilter,
    odom: np.ndarray,
    ranges: np.ndarray,
    angles: np.ndarray,
    range_max: float,
    pairs: np.ndarray,
    truth: np.ndarray,
    *,
    start: int,
    max_distance: float = 60.0,
    proba: np.ndarray | None = None,
    threshold: float = 0.5,
    snapshot_at: tuple[int, ...] = (),
    kidnap_at: int | None = None,
) -> GlobalRun:
    """Feed ``pf`` (already initialised) the scans from ``start`` on (see the module
    docstring). ``kidnap_at``: from that scan on, errors count only after it (the distance
    is measured from it): the run measures recovery."""
    driven = odometry_distance(odom[start:])
    ref = {int(i): int(j) for i, j in pairs}
    errors: list[float] = []
    at: list[int] = []
    snaps: dict[int, np.ndarray] = {}
    seconds = 0.0
    stop = start + int(np.searchsorted(driven, max_distance, side="right"))
    for i in range(start, min(stop, odom.shape[0])):
        t0 = time.perf_counter()
        pf.update(odom[i], ranges[i], angles, range_max=range_max, proba=None if proba is None else proba[i])
        seconds += time.perf_counter() - t0
        if i in snapshot_at:
            snaps[i] = pf.world_particles()
        if i in ref and (kidnap_at is None or i >= kidnap_at):
            e = pf.estimate()
            t = truth[ref[i]]
            errors.append(math.hypot(e.pose[0] - t[0], e.pose[1] - t[1]))
            at.append(i)
    err = np.asarray(errors)
    idx = np.asarray(at, dtype=np.int64)
    d = driven[idx - start] if idx.size else np.zeros(0)
    if kidnap_at is not None and idx.size:
        d = d - driven[kidnap_at - start]
    k = convergence(err, threshold)
    return GlobalRun(
        start=start,
        converged=k is not None,
        distance=float(d[k]) if k is not None else math.nan,
        errors=err,
        at=idx,
        driven=d,
        final_error=float(err[-1]) if err.size else math.nan,
        updates=pf.updates,
        seconds=seconds,
        snapshots=snaps,
    )
