"""A pose graph over keyframes with loop closures, optimised with gtsam.

:class:`PoseGraph` takes every scan with the laser's pose as the robot knows it (the pose
tracker's, or plain odometry) and keeps a **keyframe** each time that pose has moved
``keyframe_distance`` metres or turned ``keyframe_angle`` radians since the last one: its
beam endpoints and its pose. Between consecutive keyframes an **odometry edge** holds their
relative pose, with a noise model that grows with the step (``σ_xy = floor + k_t·d``,
``σ_θ = floor + k_r·|Δθ| + k_d·d``): the longer the step, the less it is trusted. Each new
keyframe's candidates are proposed and verified by scan matching
(:mod:`knowledge.localization.loop_closure`, every check recorded in :attr:`PoseGraph.checks`
with why it was accepted or not); an accepted one becomes a **loop edge** from the
candidate to the matched pose, with a Cauchy robust noise model, and the graph is optimised.

**Why gtsam, and why Levenberg–Marquardt.** gtsam (Georgia Tech, BSD) is a maintained
factor-graph library with ``Pose2`` between-factors, robust m-estimators and both batch and
incremental (iSAM2) solvers, as a wheel for Linux x86-64 and aarch64. The graphs here are
small (a keyframe per 0.5 m: 699 over the 373 m CSAIL log) and change only when a loop is
accepted, so a batch Levenberg–Marquardt from the current estimates is run then: at most 6
iterations and 34 ms on average per optimisation on CSAIL (docs/mapping.md), every
relinearisation re-evaluating the robust weights of all loop edges (iSAM2 relinearises only
the variables that moved past a threshold, so an old loop's weight can lag behind), and no
incremental bookkeeping is needed. iSAM2 is the next step for graphs of tens of thousands
of keyframes or an optimisation at every keyframe. **Bounded time**: the optimiser is
stepped one iteration at a time and stops at ``max_seconds`` (or ``max_iterations``, or
convergence), keeping the best estimate so far; :attr:`PoseGraph.optimisations` has the
seconds each optimisation took.

**Why Cauchy on loop edges.** A wrong loop that passed the acceptance test pulls the graph
with a weight ``1/(1 + (r/c)²)`` of its whitened residual ``r``: a loop metres away from
what the odometry edges agree on ends up with almost none, where a Gaussian one bends the
whole map towards it. Huber's weight falls only as ``c/r``, so a wrong loop keeps pulling
with a constant force, which matters when few right loops oppose it. Measured on the ring of
``tests/unit/test_loop_closure.py`` (33 right loops, then one that puts the robot 6 m back
along a corridor): ATE 0.195 m before the wrong loop, 0.194 m after it with Cauchy, 0.189 m
with Huber, 1.34 m with a Gaussian edge. The price of a redescending weight: a right loop
after a drift of many ``σ`` starts with little weight; on the same ring the first loop,
2 m (40 σ) from the drifted estimate, still closed in one optimisation, the odometry
edges' σ growing with their steps.

After an optimisation, later keyframes are placed from the newest optimised one by their
measured relative poses. :meth:`PoseGraph.corrected` places every scan the same way from the
keyframe before it. Poses are the laser's ``(x, y, theta)``, metres and radians; points
``(M, 2)`` metres in the laser's frame.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from knowledge.localization.loop_closure import LoopCheck, LoopParams, propose, verify
from knowledge.localization.se2 import between, compose

__all__ = ["ROBUST", "Keyframe", "PoseGraph", "PoseGraphParams"]

#: The loop edges' m-estimators.
ROBUST = ("cauchy", "huber", "none")


@dataclass(frozen=True)
class PoseGraphParams:
    """How :class:`PoseGraph` keeps keyframes, weighs edges and optimises.

    Attributes:
        keyframe_distance: metres of motion between keyframes.
        keyframe_angle: radians of turn between keyframes.
        odom_floor: ``(metres, radians)`` σ of an odometry edge of no motion.
        odom_translation: metres of σ per metre of the step.
        odom_rotation: radians of σ per radian of the step's turn.
        odom_rotation_per_metre: radians of σ per metre of the step.
        loop_sigma: ``(metres, radians)`` σ of a loop edge.
        robust: the loop edges' m-estimator: ``"cauchy"``, ``"huber"`` or ``"none"`` (Gaussian).
        robust_scale: the m-estimator's ``c``, in loop-edge σ.
        max_iterations: Levenberg–Marquardt iterations per optimisation.
        max_seconds: wall-clock seconds per optimisation.
        loops: loop candidates and their verification.
    """

    keyframe_distance: float = 0.5
    keyframe_angle: float = 0.5
    odom_floor: tuple[float, float] = (0.01, 0.005)
    odom_translation: float = 0.02
    odom_rotation: float = 0.02
    odom_rotation_per_metre: float = 0.005
    loop_sigma: tuple[float, float] = (0.05, 0.02)
    robust: str = "cauchy"
    robust_scale: float = 3.0
    max_iterations: int = 30
    max_seconds: float = 0.5
    loops: LoopParams = field(default_factory=LoopParams)

    def __post_init__(self) -> None:
        for name in ("keyframe_distance", "keyframe_angle", "robust_scale", "max_seconds"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"PoseGraphParams.{name} must be a positive number, got {v!r}")
        for name in ("odom_floor", "loop_sigma"):
            v = getattr(self, name)
            if len(v) != 2 or not all(math.isfinite(s) and s > 0 for s in v):
                raise ValueError(f"PoseGraphParams.{name} must be two positive numbers, got {v!r}")
        if self.robust not in ROBUST:
            raise ValueError(f"PoseGraphParams.robust must be one of {ROBUST}, got {self.robust!r}")
        if self.max_iterations < 1:
            raise ValueError(f"PoseGraphParams.max_iterations must be >= 1, got {self.max_iterations}")

    def odom_sigmas(self, step: npt.ArrayLike) -> np.ndarray:
        """``(σx, σy, σθ)`` of an odometry edge measuring ``step`` (a relative pose)."""
        s = np.asarray(step, dtype=np.float64)
        d, a = math.hypot(s[0], s[1]), abs(float(s[2]))
        xy = self.odom_floor[0] + self.odom_translation * d
        th = self.odom_floor[1] + self.odom_rotation * a + self.odom_rotation_per_metre * d
        return np.array([xy, xy, th])


@dataclass(frozen=True, eq=False)
class Keyframe:
    """A scan the graph keeps.

    Attributes:
        scan: the index of the scan (the how-manieth :meth:`PoseGraph.add`).
        stamp: seconds.
        measured: ``(3,)`` the pose it came with (tracked or odometry).
        points: ``(M, 2)`` float32 endpoints in the laser's frame.
        travel: metres along the measured path from the first keyframe.
    """

    scan: int
    stamp: float
    measured: np.ndarray
    points: np.ndarray
    travel: float


class PoseGraph:
    """Keyframes, odometry and loop edges, optimised (see the module docstring).

    Args:
        params: the parameters.
        close_loops: propose and verify loops at each keyframe (False: only collect keyframes).
    """

    def __init__(self, params: PoseGraphParams | None = None, *, close_loops: bool = True) -> None:
        self.params = params or PoseGraphParams()
        self.close_loops = close_loops
        self.keyframes: list[Keyframe] = []
        #: ``(j, k, relative pose)`` of the accepted loops
        self.loops: list[tuple[int, int, np.ndarray]] = []
        #: every verified candidate, accepted or not, in order
        self.checks: list[LoopCheck] = []
        #: seconds of each optimisation
        self.optimisations: list[float] = []
        #: Levenberg–Marquardt iterations of each optimisation
        self.iterations: list[int] = []
        self._estimates: list[np.ndarray] = []
        self._owner: list[int] = []  # per scan: the keyframe at or before it
        self._measured: list[np.ndarray] = []  # per scan: the pose it came with

    def __len__(self) -> int:
        return len(self.keyframes)

    @property
    def estimates(self) -> np.ndarray:
        """``(K, 3)`` the keyframes' current (optimised) poses."""
        return np.array(self._estimates).reshape(-1, 3)

    @property
    def travel(self) -> np.ndarray:
        return np.array([kf.travel for kf in self.keyframes])

    def add(self, stamp: float, pose: npt.ArrayLike, points: npt.ArrayLike) -> Keyframe | None:
        """One scan: its stamp, the laser's ``pose`` as the robot knows it, its endpoints
        ``(M, 2)``. Returns the keyframe it became, or None."""
        p = np.asarray(pose, dtype=np.float64).copy()
        self._measured.append(p)
        prm = self.params
        last = self.keyframes[-1] if self.keyframes else None
        if last is not None:
            d = between(last.measured, p)
            if math.hypot(d[0], d[1]) < prm.keyframe_distance and abs(d[2]) < prm.keyframe_angle:
                self._owner.append(len(self.keyframes) - 1)
                return None
            travel = last.travel + math.hypot(d[0], d[1])
            estimate = compose(self._estimates[-1], d)
        else:
            travel, estimate = 0.0, p
        kf = Keyframe(len(self._measured) - 1, float(stamp), p, np.asarray(points, dtype=np.float32), travel)
        self.keyframes.append(kf)
        self._estimates.append(estimate)
        self._owner.append(len(self.keyframes) - 1)
        if self.close_loops:
            accepted = [c for c in self._check(len(self.keyframes) - 1) if c.accepted]
            if accepted:
                for c in accepted:
                    assert c.relative is not None
                    self.loops.append((c.candidate, c.current, c.relative))
                self.optimise()
        return kf

    def add_loop(self, j: int, k: int, relative: npt.ArrayLike) -> None:
        """A loop edge from keyframe ``j`` to keyframe ``k`` measuring ``relative`` (``k``'s pose
        in ``j``'s frame), found some other way; taken at the next :meth:`optimise`."""
        if not (0 <= j < len(self.keyframes) and 0 <= k < len(self.keyframes)) or j == k:
            raise ValueError(f"a loop joins two keyframes of the {len(self.keyframes)}, got {j} and {k}")
        self.loops.append((j, k, np.asarray(relative, dtype=np.float64).copy()))

    def check(self, k: int, j: int, prior: npt.ArrayLike | None = None) -> LoopCheck:
        """Verify keyframe ``k`` against candidate ``j`` from ``prior`` (default: ``k``'s
        estimate), without adding anything to the graph."""
        est = self.estimates
        kfs = self.keyframes
        travel = self.travel
        lp = self.params.loops
        near = [
            i
            for i in range(len(kfs))
            if abs(travel[i] - travel[j]) <= lp.local_map_travel and travel[k] - travel[i] >= lp.min_travel
        ]
        neighbours = [(est[i], kfs[i].points.astype(np.float64)) for i in near]
        start = est[k] if prior is None else np.asarray(prior, dtype=np.float64)
        return verify(k, j, kfs[k].points, start, neighbours, est[j], float(abs(travel[k] - travel[j])), lp)

    def _check(self, k: int) -> list[LoopCheck]:
        out = []
        for j, _, _ in propose(k, self.estimates, self.travel, self.params.loops):
            c = self.check(k, j)
            self.checks.append(c)
            out.append(c)
        return out

    def optimise(self) -> float:
        """Optimise the graph from the current estimates (bounded: the module docstring);
        returns the seconds it took."""
        import gtsam

        prm = self.params
        t0 = time.perf_counter()
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        est = self._estimates
        graph.add(
            gtsam.PriorFactorPose2(
                0, gtsam.Pose2(*est[0]), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 1e-3, 1e-4]))
            )
        )
        for i, e in enumerate(est):
            values.insert(i, gtsam.Pose2(*e))
        for i in range(1, len(self.keyframes)):
            step = between(self.keyframes[i - 1].measured, self.keyframes[i].measured)
            noise = gtsam.noiseModel.Diagonal.Sigmas(prm.odom_sigmas(step))
            graph.add(gtsam.BetweenFactorPose2(i - 1, i, gtsam.Pose2(*step), noise))
        gauss = gtsam.noiseModel.Diagonal.Sigmas(
            np.array([prm.loop_sigma[0], prm.loop_sigma[0], prm.loop_sigma[1]])
        )
        loop_noise: gtsam.noiseModel.Base
        if prm.robust == "none":
            loop_noise = gauss
        else:
            kind = (
                gtsam.noiseModel.mEstimator.Cauchy
                if prm.robust == "cauchy"
                else gtsam.noiseModel.mEstimator.Huber
            )
            loop_noise = gtsam.noiseModel.Robust.Create(kind.Create(prm.robust_scale), gauss)
        for j, k, rel in self.loops:
            graph.add(gtsam.BetweenFactorPose2(j, k, gtsam.Pose2(*rel), loop_noise))
        lm = gtsam.LevenbergMarquardtParams()
        lm.setMaxIterations(prm.max_iterations)
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, lm)
        error = opt.error()
        n = 0
        while n < prm.max_iterations and time.perf_counter() - t0 < prm.max_seconds:
            opt.iterate()
            n += 1
            new = opt.error()
            if error - new <= 1e-6 * max(error, 1e-12):
                break
            error = new
        result = opt.values()
        self._estimates = [
            np.array([(q := result.atPose2(i)).x(), q.y(), q.theta()]) for i in range(len(est))
        ]
        seconds = time.perf_counter() - t0
        self.optimisations.append(seconds)
        self.iterations.append(n)
        return seconds

    def corrected(self) -> np.ndarray:
        """``(n, 3)`` every scan added so far, placed from the keyframe at or before it by
        its measured relative pose (the keyframes themselves at their estimates)."""
        est = self._estimates
        out = np.empty((len(self._measured), 3))
        for i, (m, k) in enumerate(zip(self._measured, self._owner, strict=True)):
            out[i] = compose(est[k], between(self.keyframes[k].measured, m))
        return out
