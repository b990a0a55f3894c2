"""The agent's per-scan core: synchronous, deterministic, no I/O.

``Pipeline.process(scan, pose)`` takes one laser scan and the robot's odometry pose at the
scan's stamp (:mod:`agent.core.odom_sync`) and runs, in this order:

1. the laser's pose: the robot pose composed with the laser's mount (every position below,
   graph nodes included, is the laser's, in the odometry frame); with ``localization``
   (``[localization]``, off unless configured) that pose is corrected by matching the scan
   against the map built so far (:class:`~knowledge.localization.tracking.PoseTracker`) and
   everything below lives in the corrected ``map`` frame (:attr:`StepResult.correction` is
   the map → odom transform); with ``tracking_lag`` ``L > 0`` (``[localization] lag``, the
   agent's default) the tracker runs on a worker thread of its own, one scan after the other,
   and scan ``k`` is corrected with the map → odom transform the tracker found for scan
   ``k − L``: the matching (4–9 ms) leaves the per-scan path, and because the lag is a fixed
   number of scans, not "the newest result", a replay corrects every scan as the live run
   did; the chain waits for the tracker only when it is more than ``L`` scans behind
   (:attr:`Pipeline.tracking_waits`);
1a. people (``[people]``, on by default): the leg detector, leg pairing and tracking of
   :class:`~knowledge.people.pipeline.PeoplePipeline` on the scan as measured, tracks in the
   odometry frame (:attr:`StepResult.people`); with ``mask`` the beams of the legs of
   people tracked walking (a confirmed track that moved ``min_travel`` from where it was
   born, :func:`~knowledge.people.masking.tracked_legs`, whose legs do not stand on cells
   the laser has hit for seconds, :class:`~knowledge.people.static.StaticCells`: furniture
   taken for legs stays put)
   (:func:`~knowledge.people.masking.person_beams`) are hidden: the classifier's scan gets
   the walls behind them continued (:func:`~knowledge.people.masking.fill_masked`), the
   local map gets no information there (:func:`~knowledge.people.masking.unknown_masked`);
   a 360° laser's doorway detector sees the scan as measured (the leg detector takes door
   jambs passed closely for legs), a front laser's sees the local map, which remembers the
   jambs; docs/people.md "In the agent" has the measurements behind this;
2. a front laser (less than a full turn): its beam endpoints go into the sparse local map
   and the 360° scan gets its rear beams from that map, beams without a hit interpolated
   (Sect. 3.5, :func:`~knowledge.metric.rear_beams.assemble_scan`); a 360° laser is only
   resampled to the model's beams. The share of beams that are known, not interpolated, is
   the scan's :attr:`StepResult.coverage` (0.5 for a front laser right after start-up);
3. the place model's histogram over the classes (probabilistic decision list, Sect. 4.3);
3a. the trajectory HMM (Sect. 5.4, ``[places]``, on when the model carries one): the
   histogram is the observation, Move when the laser has moved ``move_min`` since the last
   Move, else Stay (:class:`~knowledge.learning.hmm.HMMFilter`); the label is the most
   probable class of the filtered belief (``vote = "filtered"``) or of the raw histogram
   (``"raw"``), and it is what votes for navigation nodes; a scan below the graph's
   ``min_coverage`` is no observation (the belief stays; until the first observation the
   raw histogram's class is the label);
4. the doorway detector on the obstacle points around the robot (the local map's for a
   front laser, the scan's for a 360° laser);
5. the navigation graph (Sect. 7.2.2): node dropping, last-N label window and majority
   vote (a label votes only when the coverage is at least the graph's ``min_coverage``),
   doorway nodes;
6. the topological areas (Sect. 7.2.3) and their change events.

``Pipeline.observe(scan, pose)`` takes a scan left out by ``max_rate`` (``[laser]
max_rate``, applied by the sensor loop by the scans' stamps): only 1a, the local map of 2 and
4 run, with the correction the last processed scan was given; a doorway 4 reports there goes
into the graph with the next processed scan.

The result depends only on the sequence of ``(scan, pose)`` inputs (and the model and
parameters): a live run and a replay of its recording build the same graph.

Documents: :meth:`Pipeline.state_document` is the persisted ``loci.navgraph/1`` document
(:mod:`knowledge.topology.persistence`, graph and areas with votes and ids);
:func:`graph_message` and :func:`areas_message` turn such a document into the slim
``loci.graph/1`` and ``loci.areas/1`` messages the bus carries; :func:`place_message` is
the ``loci.place/1`` message of one step. :meth:`Pipeline.from_state` resumes from a
persisted document.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from agent.tables import build_dataclass, dataclass_table
from drivers.messages import LaserScan, Pose2D
from knowledge.learning.hmm import HMMFilter
from knowledge.localization.confidence import Confidence, ConfidenceTracker
from knowledge.localization.scan_matching import MatchParams
from knowledge.localization.se2 import compose as se2_compose
from knowledge.localization.se2 import inverse as se2_inverse
from knowledge.localization.tracking import PoseTracker, TrackingParams, TrackStep
from knowledge.metric.local_map import LocalMap, LocalMapParams, beam_endpoints
from knowledge.metric.rear_beams import FullScanParams, assemble_scan
from knowledge.navigation.doorways import Doorway, DoorwayDetector, DoorwayParams, scan_points
from knowledge.navigation.graph import DOORWAY, GraphParams, GraphUpdate, NavigationGraph
from knowledge.people.detector import LegDetector
from knowledge.people.masking import fill_masked, person_beams, tracked_legs, unknown_masked
from knowledge.people.pipeline import PeopleFrame, PeoplePipeline
from knowledge.people.static import StaticCells
from knowledge.places.model import PlaceModel
from knowledge.topology import persistence
from knowledge.topology.areas import AreaEvent, AreaMap

if TYPE_CHECKING:  # the configuration file's types; the core itself opens no session
    from agent.config import AgentConfig

__all__ = [
    "DOORWAY_INPUTS",
    "PeopleParams",
    "Pipeline",
    "PipelineParams",
    "PlaceFilterParams",
    "StepResult",
    "areas_message",
    "graph_message",
    "place_message",
    "smooth_correction",
]

TWO_PI = 2.0 * math.pi
#: Metres, radians: a change of the tracker's correction larger than this is taken at once,
#: not smoothed (``tracking_smoothing``): odometry that stalled and jumped, a recovery.
SMOOTHING_JUMP = (0.2, 0.1)
#: What the doorway detector of a 360° laser (which sees the current scan) gets where legs
#: were detected: ``"raw"`` (the legs as obstacles; the default: the leg detector takes door
#: jambs passed at arm's length for legs, and hiding them hid the door in 5 of 8 tour runs),
#: ``"unknown"`` (no points there), ``"filled"`` (what the classifier sees). A front laser's
#: doorway detector sees the local map, which has no legs but remembers the jambs from the
#: scans before. docs/people.md "In the agent".
DOORWAY_INPUTS = ("raw", "unknown", "filled")


@dataclass(frozen=True)
class PeopleParams:
    """People in the pipeline (``[people]``).

    Attributes:
        enabled: detect and track people in every scan.
        mask: hide the beams of detected legs from the classifier, the local map and the
            doorway detector (needs ``enabled``).
        margin: beams added on each side of a leg (mixed pixels, see
            :func:`~knowledge.people.masking.person_beams`).
        clearance: metres; only legs standing this much in front of what is beside them
            are masked (:func:`~knowledge.people.masking.free_standing`; 0: every leg).
        min_travel: metres; only the legs of a confirmed track that has moved this far from
            where it was born are masked (:func:`~knowledge.people.masking.tracked_legs`):
            furniture the leg detector takes for legs never moves. None: every detected leg
            (on real office scans that masked beams in 78 % of the scans; docs/real_logs.md).
        doorways: what a 360° laser's doorway detector sees where legs were (:data:`DOORWAY_INPUTS`).
    """

    enabled: bool = True
    mask: bool = True
    margin: int = 1
    clearance: float = 0.2
    min_travel: float | None = 1.0
    doorways: str = "raw"

    def __post_init__(self) -> None:
        if self.margin < 0:
            raise ValueError(f"margin must be a number of beams >= 0, got {self.margin}")
        if not (math.isfinite(self.clearance) and self.clearance >= 0):
            raise ValueError(f"clearance must be a distance >= 0 metres, got {self.clearance}")
        if self.min_travel is not None and not (math.isfinite(self.min_travel) and self.min_travel >= 0):
            raise ValueError(f"min_travel must be None or a distance >= 0 metres, got {self.min_travel}")
        if self.doorways not in DOORWAY_INPUTS:
            raise ValueError(f"doorways must be one of {DOORWAY_INPUTS}, got {self.doorways!r}")

    @property
    def masking(self) -> bool:
        return self.enabled and self.mask


#: Which histogram gives the label that is published and votes for navigation nodes.
VOTES = ("filtered", "raw")


@dataclass(frozen=True)
class PlaceFilterParams:
    """The place label along the trajectory (``[places]``).

    Attributes:
        hmm: filter the histograms with the model's HMM (Sect. 5.4) when it has one.
        vote: the label published and voted for nodes: the filtered belief's class
            ("filtered") or the raw histogram's ("raw"); without an HMM it is the raw one.
    """

    hmm: bool = True
    vote: str = "filtered"

    def __post_init__(self) -> None:
        if self.vote not in VOTES:
            raise ValueError(f"vote must be one of {VOTES}, got {self.vote!r}")


@dataclass(frozen=True)
class PipelineParams:
    """Everything besides the model that the pipeline's result depends on.

    Attributes:
        mount: the laser's pose on the robot ``(x, y, yaw)``: metres, metres, radians.
        local_map: the sparse local map of a front laser.
        rear_beams: rear-beam simulation (``n_beams`` and ``max_range`` are the model's).
        graph: the navigation graph (node distance d, label window N, ...).
        doorways: the doorway detector.
        people: people detection and masking.
        localization: pose tracking by scan matching (None: trust the odometry).
        tracking_lag: scans; 0: the tracker runs in :meth:`Pipeline.process`; ``L > 0``: on
            its own thread, scan ``k`` corrected with scan ``k − L``'s result (see the module
            docstring).
        tracking_smoothing: seconds; the correction a scan is given follows the tracker's
            with this time constant, small changes only (0: the tracker's as it is; see
            :meth:`Pipeline.correction`).
        places: the HMM filter of the place labels and which label votes.
        max_rate: scans per second the chain processes at most (``[laser] max_rate``; 0:
            every scan). Applied by the sensor loop before :meth:`Pipeline.process`, by the
            scans' stamps (:class:`~agent.core.sensor_loop.SensorLoop`); kept here because
            the result depends on it, so a replay leaves out the scans the robot left out.
    """

    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)
    local_map: LocalMapParams = field(default_factory=LocalMapParams)
    rear_beams: FullScanParams = field(default_factory=FullScanParams)
    graph: GraphParams = field(default_factory=GraphParams)
    doorways: DoorwayParams = field(default_factory=DoorwayParams)
    people: PeopleParams = field(default_factory=PeopleParams)
    localization: TrackingParams | None = None
    places: PlaceFilterParams = field(default_factory=PlaceFilterParams)
    tracking_lag: int = 0
    tracking_smoothing: float = 0.0
    max_rate: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.max_rate, bool) or not (math.isfinite(self.max_rate) and self.max_rate >= 0):
            raise ValueError(f"max_rate must be scans per second >= 0 (0: every scan), got {self.max_rate!r}")
        if (
            isinstance(self.tracking_lag, bool)
            or not isinstance(self.tracking_lag, int)
            or not 0 <= self.tracking_lag <= 100
        ):
            raise ValueError(
                f"tracking_lag must be a whole number of scans in [0, 100], got {self.tracking_lag!r}"
            )
        if not (math.isfinite(self.tracking_smoothing) and 0.0 <= self.tracking_smoothing <= 10.0):
            raise ValueError(
                f"tracking_smoothing must be seconds in [0, 10], got {self.tracking_smoothing!r}"
            )
        m = tuple(float(v) for v in self.mount)
        if len(m) != 3 or not all(math.isfinite(v) for v in m):
            raise ValueError(f"mount must be a finite (x [m], y [m], yaw [rad]), got {self.mount!r}")
        object.__setattr__(self, "mount", m)

    @classmethod
    def from_config(cls, config: AgentConfig) -> PipelineParams:
        return cls(
            mount=config.laser.mount.pose,
            local_map=config.local_map,
            rear_beams=config.rear_beams,
            graph=config.navigation,
            doorways=config.doorways,
            people=PeopleParams(enabled=config.people.enabled, mask=config.people.mask),
            localization=config.localization.tracking_params(),
            places=PlaceFilterParams(hmm=config.places.hmm, vote=config.places.vote),
            tracking_lag=config.localization.lag if config.localization.tracking else 0,
            tracking_smoothing=config.localization.smoothing if config.localization.tracking else 0.0,
            max_rate=config.laser.max_rate,
        )

    def to_table(self) -> dict[str, Any]:
        """Plain JSON-able values (stored in recordings so a replay uses the same parameters)."""
        extra: dict[str, Any] = {}
        if self.localization is not None:
            extra["localization"] = dataclass_table(self.localization)
            if self.tracking_lag:  # absent: the tracker ran in the per-scan path (older recordings)
                extra["tracking_lag"] = self.tracking_lag
            if self.tracking_smoothing:  # absent: not smoothed (older recordings)
                extra["tracking_smoothing"] = self.tracking_smoothing
        if self.max_rate:  # absent: every scan (older recordings)
            extra["max_rate"] = self.max_rate
        return extra | {
            "mount": list(self.mount),
            "local_map": dataclass_table(self.local_map),
            "rear_beams": dataclass_table(self.rear_beams),
            "graph": dataclass_table(self.graph),
            "doorways": dataclass_table(self.doorways),
            "people": dataclass_table(self.people),
            "places": dataclass_table(self.places),
        }

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> PipelineParams:
        """The inverse of :meth:`to_table` (unknown keys are a ConfigError).

        A table without ``people`` was written before the pipeline detected people: people
        are off, so a replay of an old recording builds the graph it built; likewise a table
        without ``places`` was written before the HMM filter: it is off.
        """
        from knowledge.errors import ConfigError

        known = {
            *("mount", "local_map", "rear_beams", "graph", "doorways", "people", "localization", "places"),
            "tracking_lag",
            "tracking_smoothing",
            "max_rate",
        }
        unknown = sorted(set(table) - known)
        if unknown:
            raise ConfigError(f"pipeline parameters: unknown key {unknown[0]!r}")
        mount = table.get("mount", [0.0, 0.0, 0.0])
        if not isinstance(mount, list | tuple) or len(mount) != 3:
            raise ConfigError(f"pipeline parameters: mount must be [x, y, yaw], got {mount!r}")
        return cls(
            mount=(float(mount[0]), float(mount[1]), float(mount[2])),
            # a table without "grazing" was written before the grazing-beam rule, one without
            # "bracket" before the two-beam rule: neither (as recorded)
            local_map=build_dataclass(
                LocalMapParams, {"grazing": None, "bracket": False, **table.get("local_map", {})}, "local_map"
            ),
            rear_beams=build_dataclass(FullScanParams, table.get("rear_beams", {}), "rear_beams"),
            graph=build_dataclass(GraphParams, table.get("graph", {}), "graph"),
            doorways=build_dataclass(DoorwayParams, table.get("doorways", {}), "doorways"),
            people=build_dataclass(PeopleParams, table.get("people", {"enabled": False}), "people"),
            localization=_tracking_from(table["localization"]) if table.get("localization") else None,
            places=build_dataclass(PlaceFilterParams, table.get("places", {"hmm": False}), "places"),
            tracking_lag=_lag_from(table.get("tracking_lag", 0)),
            tracking_smoothing=_smoothing_from(table.get("tracking_smoothing", 0.0)),
            max_rate=_rate_from(table.get("max_rate", 0.0)),
        )


@dataclass(frozen=True, eq=False)
class StepResult:
    """What one :meth:`Pipeline.process` did.

    Attributes:
        scan: the input scan.
        pose: the laser's pose in the odometry frame at the scan's stamp.
        ranges: ``(n,)`` float32 the 360° scan the model classified (beam ``i`` at ``i·2π/n``
            from the laser's heading, metres).
        label: the class published and voted for nodes (``[places] vote``).
        probabilities: class → probability of the histogram ``label`` comes from (the
            filtered belief with ``vote = "filtered"`` and an HMM, else the model's histogram).
        doorway: a doorway the robot just passed through, or None.
        in_opening: the robot is inside a door-like opening now.
        update: what the navigation graph did.
        events: the areas' change events.
        people: the people of this scan (None: people detection is off).
        masked: ``(B,)`` bool, the scan's beams hidden as people (None: nothing hidden).
        coverage: the share of ``ranges``' beams measured or hit in the local map (the rest
            are interpolated); below the graph's ``min_coverage`` the label did not vote.
        correction: ``(3,)`` the map → odom transform of pose tracking (None: tracking off;
            ``pose`` is then in the odometry frame, else in ``map``).
        raw_probabilities: class → probability, the model's histogram of this scan (eq. 4.5).
        filtered: class → probability, the HMM's belief after this scan (None: no HMM).
        localization: how sure the corrected pose is (``[localization]``; None: tracking off,
            or no scan matched yet): the tracker's verdict on scan ``k − L`` with a lag
            (:class:`~knowledge.localization.confidence.Confidence`).
    """

    scan: LaserScan
    pose: Pose2D
    ranges: np.ndarray
    label: str
    probabilities: Mapping[str, float]
    doorway: Doorway | None
    in_opening: bool
    update: GraphUpdate
    events: tuple[AreaEvent, ...]
    people: PeopleFrame | None = None
    masked: np.ndarray | None = None
    coverage: float = 1.0
    correction: np.ndarray | None = None
    raw_probabilities: Mapping[str, float] = field(default_factory=dict)
    filtered: Mapping[str, float] | None = None
    localization: Confidence | None = None

    @property
    def raw_label(self) -> str:
        """The most probable class of the model's own histogram."""
        raw = self.raw_probabilities or self.probabilities
        return max(raw, key=lambda c: raw[c])

    @property
    def stamp(self) -> float:
        return self.scan.stamp

    @property
    def node(self) -> int | None:
        """The navigation node the robot was last at."""
        return self.update.current

    @property
    def graph_changed(self) -> bool:
        """Whether the ``loci.graph/1`` message changed (nodes, edges, labels, a doorway's width)."""
        return self.update.changed or self.doorway is not None

    @property
    def areas_changed(self) -> bool:
        """Whether the areas may have changed (they are recomputed from the graph)."""
        return self.update.changed or bool(self.events)

    @property
    def state_changed(self) -> bool:
        """Whether the persisted document changed beyond the label window (votes, visits)."""
        u = self.update
        return bool(u.added or u.reached or u.relabelled or u.edges) or self.doorway is not None


def compose(pose: Pose2D, mount: tuple[float, float, float]) -> np.ndarray:
    """``(3,)`` the laser's odometry-frame pose: ``pose`` ⊕ ``mount``."""
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    mx, my, myaw = mount
    th = pose.theta + myaw
    return np.array(
        [pose.x + c * mx - s * my, pose.y + s * mx + c * my, math.atan2(math.sin(th), math.cos(th))]
    )


def is_full_turn(scan: LaserScan) -> bool:
    """Whether the scan's beams cover the full turn (a 360° laser)."""
    return scan.n_beams * scan.angle_increment >= TWO_PI - 1e-6


class Pipeline:
    """The per-scan chain (see the module docstring).

    Args:
        model: the place model; its ``scan`` parameters fix the 360° scan's beams and range.
        params: everything else.
        graph, areas: a graph (and its areas) to continue (see :meth:`from_state`).
        people_detector: the leg detector (default: the bundled model, loaded when
            ``params.people.enabled``).
    """

    def __init__(
        self,
        model: PlaceModel,
        params: PipelineParams | None = None,
        *,
        graph: NavigationGraph | None = None,
        areas: AreaMap | None = None,
        people_detector: LegDetector | None = None,
    ) -> None:
        prm = params or PipelineParams()
        self.model = model
        self.params = replace(
            prm,
            rear_beams=replace(prm.rear_beams, n_beams=model.scan.n_beams, max_range=model.scan.max_range),
        )
        self.classes = tuple(model.classes)
        hmm = model.hmm if self.params.places.hmm else None
        self.hmm: HMMFilter | None = HMMFilter(hmm) if hmm is not None else None
        self._hmm_observed = False  # the filter has had a scan with enough coverage
        self.local_map = LocalMap(self.params.local_map)
        pp = self.params.people
        self.people: PeoplePipeline | None = PeoplePipeline(people_detector) if pp.enabled else None
        self._static = StaticCells()  # what has stood still: furniture legs are not masked
        self.detector = DoorwayDetector(self.params.doorways)
        self.graph = graph if graph is not None else NavigationGraph(self.params.graph)
        self.areas = areas if areas is not None else AreaMap()
        self.areas.update(self.graph)
        self.scans = 0
        #: over-rate scans seen by :meth:`observe` (people, local map, doorways only)
        self.observed = 0
        self.last_stamp: float | None = None
        self._pending_doorway: Doorway | None = None
        self._angles: tuple[tuple[int, float, float], np.ndarray] | None = None
        loc = self.params.localization
        self.tracker: PoseTracker | None = PoseTracker(loc) if loc is not None else None
        self._confidence = ConfidenceTracker(loc.noise_floor if loc is not None else (0.03, 0.03))
        self._lag = self.params.tracking_lag if self.tracker is not None else 0
        self._track_pool: ThreadPoolExecutor | None = None
        self._track_jobs: deque[Future[TrackStep]] = deque()
        self._correction = np.zeros(3)  # map -> odom the tracker found (scan k - L's); starts at identity
        self._applied = np.zeros(3)  # map -> odom the latest scan was given (smoothed)
        self._applied_stamp: float | None = None
        #: milliseconds the tracker took per scan (the newest 1000), wherever it ran
        self.tracking_ms: deque[float] = deque(maxlen=1000)
        #: scans that waited for a tracker more than ``tracking_lag`` scans behind
        self.tracking_waits = 0
        #: scans the tracker failed on (on its thread): the correction before stands
        self.tracking_errors = 0
        self.last_tracking_error: str | None = None

    @property
    def correction(self) -> np.ndarray | None:
        """``(3,)`` the map → odom transform the latest scan was corrected with (None:
        tracking off). With a ``tracking_lag`` this is scan ``k − L``'s, not the tracker's newest.

        With ``tracking_smoothing`` τ it follows the tracker's correction smoothly: each scan
        moves the corrected pose the fraction ``1 − exp(−Δt/τ)`` of the way from where the
        previous correction puts it to where the tracker's puts it, unless the two lie more
        than :data:`SMOOTHING_JUMP` apart (odometry that jumped: taken at once). Each match
        has its own noise (the scan's stamp jitters by milliseconds, and turning at 2 rad/s
        that is a degree of heading): applied as it comes, scan after scan, it shakes the local
        map, whose points a beam at a grazing angle then "sees through" and clears (the
        furniture's sides beside the tour's false doorway vanished so, and with them the
        doorway). The odometry's drift the correction is there for is slow.
        """
        return None if self.tracker is None else self._applied.copy()

    def _smoothed(self, raw: np.ndarray, sensor: np.ndarray, stamp: float) -> np.ndarray:
        """The correction scan ``sensor`` (odometry pose) at ``stamp`` is given, from the
        tracker's ``raw`` one (see :attr:`correction`)."""
        tau = self.params.tracking_smoothing
        applied = raw
        if tau > 0.0 and self._applied_stamp is not None:
            applied = smooth_correction(self._applied, raw, sensor, stamp - self._applied_stamp, tau)
        self._applied = np.array(applied, dtype=np.float64)
        self._applied_stamp = stamp
        return self._applied

    def close(self) -> None:
        """Stop the tracker's thread (if it runs on one); pending scans are dropped."""
        if self._track_pool is not None:
            self._track_pool.shutdown(wait=True, cancel_futures=True)
            self._track_pool = None
            self._track_jobs.clear()

    def _timed_track(
        self, ranges: np.ndarray, angles: np.ndarray, sensor: np.ndarray, scan: LaserScan
    ) -> TrackStep:
        assert self.tracker is not None
        t0 = time.perf_counter()
        step = self.tracker.update(ranges, angles, sensor, range_max=scan.range_max, range_min=scan.range_min)
        self.tracking_ms.append((time.perf_counter() - t0) * 1e3)
        return step

    def _pose_before_tracking(self, sensor: np.ndarray, stamp: float) -> np.ndarray:
        """The laser's map pose known before this scan is matched: with a lag, the final one
        (scan ``k − L``'s correction, collected here); inline, the tracker's prediction."""
        if self._lag and len(self._track_jobs) >= self._lag:
            job = self._track_jobs.popleft()
            if not job.done():
                self.tracking_waits += 1
            try:
                done = job.result()
                self._correction = done.correction
                self._confidence.update(done)
            except Exception as exc:  # that scan's match is lost, not this scan
                self.tracking_errors += 1
                self.last_tracking_error = f"{type(exc).__name__}: {exc}"
        assert self.tracker is not None
        if self._lag:
            return se2_compose(self._smoothed(self._correction, sensor, stamp), sensor)
        c = self._applied if self.tracker.correction is None else self.tracker.correction
        return se2_compose(c, sensor)

    def _track(
        self, scan: LaserScan, ranges: np.ndarray, angles: np.ndarray, sensor: np.ndarray, pose: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Match ``ranges`` (the scan, people hidden) from the odometry pose ``sensor``: the
        laser's pose in the map and the map → odom correction it was given (with a lag the
        match runs on the tracker's thread and ``pose``, from :meth:`_pose_before_tracking`, stands)."""
        if self._lag == 0:
            step = self._timed_track(ranges, angles, sensor, scan)
            self._correction = step.correction
            self._confidence.update(step)
            applied = self._smoothed(step.correction, sensor, scan.stamp)
            if self.params.tracking_smoothing == 0.0:
                return step.pose, step.correction
            return se2_compose(applied, sensor), applied.copy()
        if self._track_pool is None:
            self._track_pool = ThreadPoolExecutor(1, thread_name_prefix="loci-tracking")
        self._track_jobs.append(self._track_pool.submit(self._timed_track, ranges, angles, sensor, scan))
        return pose, self._applied.copy()

    # ------------------------------------------------------------------ per scan
    def _beam_angles(self, scan: LaserScan) -> np.ndarray:
        key = (scan.n_beams, scan.angle_min, scan.angle_increment)
        if self._angles is None or self._angles[0] != key:
            self._angles = (key, scan.angles)
        return self._angles[1]

    def _check_order(self, scan: LaserScan) -> None:
        if self.last_stamp is not None and scan.stamp < self.last_stamp:
            raise ValueError(
                f"scan stamps must not go back in time ({scan.stamp} after {self.last_stamp}); "
                "associate scans with odometry through agent.core.odom_sync.OdomSync"
            )

    def _masked(
        self, scan: LaserScan, frame: PeopleFrame | None, angles: np.ndarray, sensor: np.ndarray, full: bool
    ) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """The people mask and the ranges each consumer gets: ``(mask, classifier's, local
        map's, doorway detector's)`` (all the raw ranges when nobody walks in the scan)."""
        raw = scan.ranges
        if self.people is None or not self.params.people.mask:
            return None, raw, raw, raw
        assert frame is not None
        pp = self.params.people
        walking = None
        if pp.min_travel is not None:
            self._static.update(
                beam_endpoints(raw, angles, sensor, range_max=scan.range_max, range_min=scan.range_min),
                scan.stamp,
            )
            walking = tracked_legs(
                frame.detection,
                frame.legs,
                frame.tracks,
                min_travel=pp.min_travel,
                standing=self._static.static(frame.legs) if frame.legs.shape[0] else None,
            )
        m = person_beams(frame.detection, margin=pp.margin, clearance=pp.clearance or None, persons=walking)
        if not m.any():
            return None, raw, raw, raw
        cls_r = fill_masked(
            raw,
            m,
            range_max=scan.range_max,
            range_min=scan.range_min,
            circular=full,
            angle_min=scan.angle_min,
            angle_increment=scan.angle_increment,
        )
        map_r = unknown_masked(raw, m)
        door_r = {"unknown": map_r, "raw": raw, "filled": cls_r}[pp.doorways]
        return m, cls_r, map_r, door_r

    def _doorway_points(
        self, scan: LaserScan, map_r: np.ndarray, door_r: np.ndarray, angles: np.ndarray, sensor: np.ndarray
    ) -> np.ndarray:
        """The obstacle points the doorway detector sees (robot frame): a 360° scan's own, a
        front laser's local map after this scan went in."""
        if is_full_turn(scan):
            return scan_points(door_r, angles, range_max=scan.range_max, range_min=scan.range_min)
        self.local_map.add(
            map_r, angles, sensor, stamp=scan.stamp, range_max=scan.range_max, range_min=scan.range_min
        )
        return self.local_map.points_in_robot_frame(sensor)

    def observe(self, scan: LaserScan, pose: Pose2D) -> None:
        """A scan left out by ``max_rate``: only what needs every scan sees it — the people
        tracker, the local map and the doorway detector (whose opening a robot may pass
        between two processed scans, and whose walls beyond the jambs the local map holds
        from many viewpoints). No classification, no tracking (the pose has the correction
        the last processed scan was given), no graph update, nothing published; a doorway
        reported here goes into the graph with the next processed scan.

        Raises:
            ValueError: the scan is older than the previous one.
        """
        self._check_order(scan)
        sensor = compose(pose, self.params.mount)
        if self.tracker is not None:
            sensor = se2_compose(self._applied, sensor)
        angles = self._beam_angles(scan)
        frame = None
        if self.people is not None:
            frame = self.people.process_scan(
                scan, sensor_pose=(float(sensor[0]), float(sensor[1]), float(sensor[2]))
            )
        _, _, map_r, door_r = self._masked(scan, frame, angles, sensor, is_full_turn(scan))
        points = self._doorway_points(scan, map_r, door_r, angles, sensor)
        doorway = self.detector.update(points, sensor, scan.stamp)
        if doorway is not None:
            self._pending_doorway = doorway
        self.observed += 1
        self.last_stamp = scan.stamp

    def process(self, scan: LaserScan, pose: Pose2D) -> StepResult:
        """Run the chain on one scan and the robot's odometry pose at its stamp.

        Raises:
            ValueError: the scan is older than the previous one (scans must come in stamp order).
        """
        self._check_order(scan)
        sensor = compose(pose, self.params.mount)
        angles = self._beam_angles(scan)
        correction = None
        frame_id = pose.frame_id
        odom_sensor = sensor
        if self.tracker is not None:
            sensor = self._pose_before_tracking(odom_sensor, scan.stamp)
            frame_id = "map"
        fsp = self.params.rear_beams
        full = is_full_turn(scan)
        frame: PeopleFrame | None = None
        raw = scan.ranges
        if self.people is not None:
            frame = self.people.process_scan(
                scan, sensor_pose=(float(sensor[0]), float(sensor[1]), float(sensor[2]))
            )
        if self.tracker is not None:
            # people are no landmarks: the legs of everyone detected (free-standing ones, not a
            # wall's end) are hidden from the matcher and its map; a tutor walking ahead
            # otherwise drags the match back along a corridor (docs/localization.md)
            track_r = raw
            if frame is not None:
                pp = self.params.people
                legs = person_beams(frame.detection, margin=pp.margin, clearance=pp.clearance or None)
                if legs.any():
                    track_r = np.where(legs, np.nan, raw).astype(raw.dtype, copy=False)
            sensor, correction = self._track(scan, track_r, angles, odom_sensor, sensor)
        mask, cls_r, map_r, door_r = self._masked(scan, frame, angles, sensor, full)
        points = self._doorway_points(scan, map_r, door_r, angles, sensor)
        if full:
            ranges, known = assemble_scan(
                cls_r, angles, range_max=scan.range_max, params=fsp, range_min=scan.range_min
            )
        else:
            ranges, known = assemble_scan(
                cls_r,
                angles,
                range_max=scan.range_max,
                pose=sensor,
                local_map=self.local_map,
                params=fsp,
                range_min=scan.range_min,
            )
        proba = np.clip(self.model.predict_proba_scans(ranges)[0], 0.0, 1.0)
        coverage = float(known.mean())
        belief: np.ndarray | None = None
        if self.hmm is not None:
            # A scan too little of which is measured does not vote for nodes, and it is no
            # observation for the HMM either (half of it is interpolated: "a small room").
            if coverage >= self.graph.params.min_coverage:
                belief = self.hmm.update(proba, (float(sensor[0]), float(sensor[1])))
                self._hmm_observed = True
            else:
                belief = np.asarray(self.hmm.belief)
        use_belief = self._hmm_observed and self.params.places.vote == "filtered"
        voted = belief if belief is not None and use_belief else proba
        label = self.classes[int(np.argmax(voted))]
        doorway = self.detector.update(points, sensor, scan.stamp)
        if doorway is None:
            # one left between two processed scans; two would need the robot to leave two
            # openings within 1 / max_rate s
            doorway = self._pending_doorway
        self._pending_doorway = None
        in_opening = self.detector.passing
        upd = self.graph.update(
            sensor, label, doorway, in_opening=in_opening, ranges=ranges, coverage=coverage, known=known
        )
        events = tuple(self.areas.update(self.graph))
        self.scans += 1
        self.last_stamp = scan.stamp
        return StepResult(
            scan=scan,
            pose=Pose2D(
                float(sensor[0]), float(sensor[1]), float(sensor[2]), stamp=scan.stamp, frame_id=frame_id
            ),
            ranges=ranges,
            label=label,
            probabilities={c: float(p) for c, p in zip(self.classes, voted, strict=True)},
            doorway=doorway,
            in_opening=in_opening,
            update=upd,
            events=events,
            people=frame,
            masked=mask,
            coverage=coverage,
            correction=correction,
            localization=self._confidence.current if self.tracker is not None else None,
            raw_probabilities={c: float(p) for c, p in zip(self.classes, proba, strict=True)},
            filtered=None
            if belief is None
            else {c: float(p) for c, p in zip(self.classes, belief, strict=True)},
        )

    # ------------------------------------------------------------------ documents
    def state_document(self, meta: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The ``loci.navgraph/1`` document of the graph and areas (what is persisted)."""
        info: dict[str, Any] = {"scans": self.scans}
        if self.last_stamp is not None:
            info["stamp"] = self.last_stamp
        return persistence.to_document(self.graph, self.areas, meta={**info, **(meta or {})})

    @classmethod
    def from_state(
        cls,
        document: Mapping[str, Any],
        model: PlaceModel,
        params: PipelineParams | None = None,
        *,
        people_detector: LegDetector | None = None,
    ) -> Pipeline:
        """A pipeline continuing the graph and areas of a ``loci.navgraph/1`` document.

        The graph keeps its nodes, votes, label window and the node the robot was last at;
        the local map and the doorway detector start empty. The parameters are ``params``'
        (the configuration wins over those stored in the document).

        Raises:
            ProtocolError: the document is malformed.
        """
        prm = params or PipelineParams()
        graph, areas = persistence.from_document(dict(document))
        graph.params = prm.graph
        graph.recent = deque(graph.recent, maxlen=prm.graph.window)
        return cls(model, prm, graph=graph, areas=areas, people_detector=people_detector)

    def messages(self, stamp: float | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        """The ``loci.graph/1`` and ``loci.areas/1`` messages of the current state."""
        doc = self.state_document()
        when = stamp if stamp is not None else (self.last_stamp or 0.0)
        return graph_message(doc, when, "map" if self.tracker is not None else "odom"), areas_message(
            doc, when
        )


def smooth_correction(
    applied: np.ndarray, raw: np.ndarray, sensor: np.ndarray, dt: float, tau: float
) -> np.ndarray:
    """One step of :attr:`Pipeline.correction`'s smoothing: the map → odom correction for
    the odometry pose ``sensor``, ``dt`` seconds after ``applied`` was given, towards the
    tracker's ``raw``, with time constant ``tau`` seconds.

    What moves smoothly is the corrected *pose* (``applied ⊕ sensor`` towards ``raw ⊕
    sensor``), not the transform's numbers: far from the odometry's origin a hundredth of a
    radian of the transform is decimetres of its translation. A pose change of more than
    :data:`SMOOTHING_JUMP` is taken at once.
    """
    before = se2_compose(applied, sensor)
    target = se2_compose(raw, sensor)
    d = target - before
    d[2] = math.atan2(math.sin(d[2]), math.cos(d[2]))
    if tau <= 0.0 or math.hypot(d[0], d[1]) > SMOOTHING_JUMP[0] or abs(d[2]) > SMOOTHING_JUMP[1]:
        return np.asarray(raw, dtype=np.float64).copy()
    a = 1.0 - math.exp(-max(dt, 0.0) / tau)
    return np.asarray(se2_compose(before + a * d, se2_inverse(sensor)), dtype=np.float64)


def _smoothing_from(value: Any) -> float:
    from knowledge.errors import ConfigError

    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 <= value <= 10.0:
        raise ConfigError(
            f"pipeline parameters: tracking_smoothing must be seconds in [0, 10], got {value!r}"
        )
    return float(value)


def _rate_from(value: Any) -> float:
    from knowledge.errors import ConfigError

    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not (math.isfinite(value) and value >= 0)
    ):
        raise ConfigError(f"pipeline parameters: max_rate must be scans per second >= 0, got {value!r}")
    return float(value)


def _lag_from(value: Any) -> int:
    from knowledge.errors import ConfigError

    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 100:
        raise ConfigError(
            f"pipeline parameters: tracking_lag must be a whole number in [0, 100], got {value!r}"
        )
    return value


def _tracking_from(table: Mapping[str, Any]) -> TrackingParams:
    t = dict(table)
    # a table without the odometry prior was written before it: none, so the replay matches
    t.setdefault("prior_translation", 0.0)
    t.setdefault("prior_rotation", 0.0)
    # ... and one without the field's kind before the incremental field: the window, remade
    t.setdefault("field", "window")
    # ... and one without these before the fallback rule and the probation of corrections:
    # the fallback on any poor fit, corrections never questioned
    t.setdefault("fallback", "poor_fit")
    t.setdefault("confirm_scans", 0)
    if "noise_floor" in t:
        t["noise_floor"] = tuple(t["noise_floor"])
    match = build_dataclass(MatchParams, t.pop("match", {}), "localization.match")
    return replace(build_dataclass(TrackingParams, t, "localization", skip=("match",)), match=match)


# ---------------------------------------------------------------------------- messages


def _num(v: float | None) -> float | None:
    return None if v is None else round(float(v), 6)


def graph_message(document: Mapping[str, Any], stamp: float, frame_id: str = "odom") -> dict[str, Any]:
    """The slim ``loci.graph/1`` message of a ``loci.navgraph/1`` document (no votes, no ids counter)."""
    nodes = []
    for n in document["nodes"]:
        node: dict[str, Any] = {
            "id": int(n["id"]),
            "x": _num(n["x"]),
            "y": _num(n["y"]),
            "kind": n["kind"],
            "label": n["label"],
        }
        if n["kind"] == DOORWAY:
            node["width"] = _num(n.get("width"))
            node["orientation"] = _num(n.get("orientation"))
        nodes.append(node)
    edges = [[int(e["source"]), int(e["target"])] for e in document["edges"]]
    return {
        "schema": "loci.graph/1",
        "stamp": float(stamp),
        "frame_id": frame_id,
        "nodes": nodes,
        "edges": edges,
    }


def areas_message(document: Mapping[str, Any], stamp: float) -> dict[str, Any]:
    """The ``loci.areas/1`` message of a ``loci.navgraph/1`` document (no areas yet: none)."""
    areas = document.get("areas") or {"areas": []}
    return {
        "schema": "loci.areas/1",
        "stamp": float(stamp),
        "areas": [
            {"id": int(a["id"]), "label": a["label"], "nodes": sorted(int(k) for k in a["nodes"])}
            for a in areas["areas"]
            if a["nodes"]
        ],
    }


def place_message(result: StepResult) -> dict[str, Any]:
    """The ``loci.place/1`` message of one step: the label and its histogram, the model's raw
    histogram and the HMM's filtered one (null without an HMM)."""
    return {
        "schema": "loci.place/1",
        "stamp": result.stamp,
        "label": result.label,
        "probabilities": dict(result.probabilities),
        "node": result.node,
        "coverage": round(result.coverage, 4),
        "pose": {
            "x": round(result.pose.x, 4),
            "y": round(result.pose.y, 4),
            "theta": round(result.pose.theta, 5),
        },
        "raw_probabilities": dict(result.raw_probabilities or result.probabilities),
        "filtered_probabilities": None if result.filtered is None else dict(result.filtered),
    }
