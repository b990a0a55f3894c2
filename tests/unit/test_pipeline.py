"""The per-scan pipeline on a scripted drive through a generated office.

Scans are ray cast from the true poses (1 cm noise), odometry is the true pose. The route
goes along the corridor, through a door into the room and back out, and on along the
corridor: the graph must have place nodes about 1 m apart, one doorway node at the door,
and the room and the corridor in different areas.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass

import numpy as np
import pytest

from agent.bus.schemas import SCHEMAS
from agent.core.pipeline import (
    PeopleParams,
    Pipeline,
    PipelineParams,
    areas_message,
    compose,
    graph_message,
    place_message,
)
from drivers.messages import LaserScan, Pose2D
from knowledge.metric.raycast import cast
from knowledge.navigation.graph import GraphParams
from knowledge.places.model import PlaceModel, default_model_path
from knowledge.topology import persistence
from sim.buildings import Building, Door, generate_building

STEP = 0.05  # metres between scans
TURN = math.radians(10)  # radians between scans when turning in place


@dataclass
class Drive:
    building: Building
    door: Door
    poses: np.ndarray  # (k, 3) true = odometry poses
    stamps: np.ndarray  # (k,) seconds


def route(building: Building, door: Door) -> np.ndarray:
    """Poses every STEP metres: corridor → door → room centre → door → corridor, turning in place."""
    n = np.array([math.cos(door.orientation), math.sin(door.orientation)])  # room → corridor
    along = np.array([-n[1], n[0]])
    c = np.array(door.center)
    x0, y0, x1, y1 = building.space(door.connects[1]).rect
    front = c + n * float(np.dot(np.array([(x0 + x1) / 2, (y0 + y1) / 2]) - c, n))
    room = np.array(building.space(door.connects[0]).center)
    waypoints = [front + 4.0 * along, front, c - 1.2 * n, room, c - 1.2 * n, front, front - 4.0 * along]
    poses: list[tuple[float, float, float]] = []
    heading: float | None = None
    for a, b in itertools.pairwise(waypoints):
        d = b - a
        h = math.atan2(d[1], d[0])
        if heading is not None:
            turn = math.atan2(math.sin(h - heading), math.cos(h - heading))
            k = int(abs(turn) / TURN)
            poses += [(a[0], a[1], heading + turn * j / (k + 1)) for j in range(1, k + 1)]
        m = max(1, int(np.hypot(*d) / STEP))
        poses += [(a[0] + d[0] * j / m, a[1] + d[1] * j / m, h) for j in range(m)]
        heading = h
    poses.append((waypoints[-1][0], waypoints[-1][1], heading or 0.0))
    return np.array(poses)


@pytest.fixture(scope="module")
def model() -> PlaceModel:
    return PlaceModel.load(default_model_path())


@pytest.fixture(scope="module")
def drive() -> Drive:
    building = generate_building(1, furniture=False, layout="straight")
    for door in building.doors:
        if building.space(door.connects[1]).kind != "corridor":
            continue
        poses = route(building, door)
        cells = building.grid.world_to_cell(poses[:, :2])
        if building.grid.free[cells[:, 0], cells[:, 1]].all():  # the route stays in the free space
            return Drive(building, door, poses, 1.7e9 + 0.1 * np.arange(len(poses)))
    raise AssertionError("no door of building 1 has a free route from the corridor")


def scans(drive: Drive, laser: str) -> list[LaserScan]:
    if laser == "front":
        n, fov, angle_min, inc = 361, math.pi, -math.pi / 2, math.pi / 360
    else:
        n, fov, angle_min, inc = 360, 2 * math.pi, 0.0, 2 * math.pi / 360
    rng = np.random.default_rng(7)
    raw = cast(drive.building.grid, drive.poses, n_beams=n, fov=fov, max_range=30.0, noise_std=0.01, rng=rng)
    return [LaserScan(float(t), i, "laser", angle_min, inc, 30.0, raw[i]) for i, t in enumerate(drive.stamps)]


def run(
    pipeline: Pipeline, drive: Drive, laser_scans: list[LaserScan], start: int = 0, stop: int | None = None
) -> None:
    for i in range(start, len(laser_scans) if stop is None else stop):
        x, y, th = drive.poses[i]
        pipeline.process(laser_scans[i], Pose2D(x, y, th, stamp=laser_scans[i].stamp))


def in_rect(xy: tuple[float, float], rect: tuple[float, float, float, float]) -> bool:
    return rect[0] <= xy[0] <= rect[2] and rect[1] <= xy[1] <= rect[3]


@pytest.mark.parametrize("laser", ["front", "360"])
def test_nodes_doorways_and_areas_of_a_drive(model: PlaceModel, drive: Drive, laser: str) -> None:
    pipeline = Pipeline(model, PipelineParams())
    run(pipeline, drive, scans(drive, laser))
    g = pipeline.graph
    place = g.place_nodes()
    doors = g.doorway_nodes()
    d = g.params.node_distance
    xy = np.array([n.xy for n in place])
    # place nodes are at least d apart, and every pose of the route is within about d of one
    gaps = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1)) + np.eye(len(xy)) * 99
    assert gaps.min() > 0.99 * d
    to_node = np.hypot(*(drive.poses[:, None, :2] - xy[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    assert to_node.max() < 1.5 * d
    # a route of about 4 + 3 + 2 × room + 3 + 4 m: roughly one node per metre
    assert 8 <= len(place) <= 30
    # one doorway node (passed twice, merged) at the door, with its width
    assert len(doors) == 1
    door = doors[0]
    assert math.hypot(door.x - drive.door.center[0], door.y - drive.door.center[1]) < 0.5
    assert door.width is not None and abs(door.width - drive.door.width) < 0.25
    # the room's nodes form an area of their own; the doorway node joins it to the corridor
    room_rect = drive.building.space(drive.door.connects[0]).rect
    room_nodes = {n.id for n in place if in_rect(n.xy, room_rect)}
    assert len(room_nodes) >= 2
    areas = pipeline.areas.areas.values()
    room_area = [a for a in areas if a.nodes & room_nodes]
    assert len(room_area) == 1 and room_area[0].nodes == room_nodes
    assert len(pipeline.areas.areas) >= 2
    assert set(g.neighbours(door.id)) & room_nodes and set(g.neighbours(door.id)) - room_nodes
    # most room nodes are labelled room (the classifier's majority vote)
    assert sum(g.nodes[k].label == "room" for k in room_nodes) >= len(room_nodes) - 1
    assert room_area[0].label == "room"


def test_coverage_grows_as_the_local_map_fills_and_gates_the_votes(model: PlaceModel, drive: Drive) -> None:
    front, full = scans(drive, "front"), scans(drive, "360")
    p = Pipeline(model, PipelineParams())
    steps = []
    for i in range(len(front)):
        x, y, th = drive.poses[i]
        steps.append(p.process(front[i], Pose2D(x, y, th, stamp=front[i].stamp)))
    cov = np.array([s.coverage for s in steps])
    # a front laser alone covers half the turn; driving, the local map fills in the rear
    assert 0.45 <= cov[0] <= 0.55
    assert cov.max() >= 0.85
    # the labels of scans below min_coverage abstained
    first_vote = int(np.argmax(cov >= p.graph.params.min_coverage))
    assert first_vote > 0
    start = p.graph.node(1)
    assert start.visits >= 1
    before = Pipeline(model, PipelineParams())
    for i in range(first_vote):
        x, y, th = drive.poses[i]
        before.process(front[i], Pose2D(x, y, th, stamp=front[i].stamp))
    assert set(before.graph.recent) <= {None} and all(n.label is None for n in before.graph.place_nodes())
    message = place_message(steps[0])
    SCHEMAS.validate(message, "loci.place/1")
    assert message["coverage"] == pytest.approx(cov[0], abs=1e-4)
    # a 360° laser measures every beam: every label votes from the first scan
    q = Pipeline(model, PipelineParams())
    x, y, th = drive.poses[0]
    r = q.process(full[0], Pose2D(x, y, th, stamp=full[0].stamp))
    assert r.coverage == 1.0 and list(q.graph.recent) == [r.label]


def test_the_same_inputs_give_the_same_documents(model: PlaceModel, drive: Drive) -> None:
    laser_scans = scans(drive, "front")
    docs = []
    for _ in range(2):
        p = Pipeline(model)
        run(p, drive, laser_scans, 0, 200)
        docs.append(persistence.dumps(p.state_document()))
    assert docs[0] == docs[1]


def test_messages_validate_and_mirror_the_document(model: PlaceModel, drive: Drive) -> None:
    laser_scans = scans(drive, "360")
    p = Pipeline(model)
    results = []
    for i in range(len(laser_scans)):
        x, y, th = drive.poses[i]
        results.append(p.process(laser_scans[i], Pose2D(x, y, th, stamp=laser_scans[i].stamp)))
    assert any(r.doorway is not None for r in results) and all(r.label in model.classes for r in results)
    assert sum(r.update.changed for r in results) >= len(p.graph) // 2
    place = place_message(results[-1])
    SCHEMAS.validate(place, "loci.place/1")
    assert place["node"] == p.graph.current and sum(place["probabilities"].values()) == pytest.approx(1.0)
    doc = p.state_document(meta={"robot": "rosie"})
    graph, areas = graph_message(doc, 5.0), areas_message(doc, 5.0)
    SCHEMAS.validate(graph, "loci.graph/1")
    SCHEMAS.validate(areas, "loci.areas/1")
    assert [n["id"] for n in graph["nodes"]] == sorted(p.graph.nodes)
    assert {tuple(e) for e in graph["edges"]} == {(a, b) for a, b, _ in p.graph.edges()}
    door = next(n for n in graph["nodes"] if n["kind"] == "doorway")
    assert door["width"] > 0.5 and door["label"] == "doorway"
    assert {a["id"]: set(a["nodes"]) for a in areas["areas"]} == {
        k: set(a.nodes) for k, a in p.areas.areas.items()
    }
    assert (graph, areas) == tuple(m | {"stamp": 5.0} for m in p.messages())


def test_resume_from_the_state_document(model: PlaceModel, drive: Drive) -> None:
    laser_scans = scans(drive, "front")
    half = len(laser_scans) // 2
    first = Pipeline(model, PipelineParams(graph=GraphParams(window=7)))
    run(first, drive, laser_scans, 0, half)
    saved = json.loads(persistence.dumps(first.state_document()))  # through JSON, as on disk
    resumed = Pipeline.from_state(saved, model, PipelineParams(graph=GraphParams(window=7)))
    before, after = first.state_document(), resumed.state_document()
    for key in ("nodes", "areas", "current", "recent_labels", "next_node_id"):
        assert after[key] == before[key], key
    # (edge lengths are recomputed from the stored, rounded positions: compare the pairs)
    assert [(e["source"], e["target"]) for e in after["edges"]] == [
        (e["source"], e["target"]) for e in before["edges"]
    ]
    assert resumed.graph.recent.maxlen == 7 and list(resumed.graph.recent) == list(first.graph.recent)
    run(resumed, drive, laser_scans, half)
    for k, node in first.graph.nodes.items():
        again = resumed.graph.nodes[k]
        assert again.kind == node.kind and (again.x, again.y) == pytest.approx((node.x, node.y), abs=1e-6)
    assert min(set(resumed.graph.nodes) - set(first.graph.nodes)) >= first.graph.next_id
    assert len(resumed.graph.doorway_nodes()) == 1  # the way back out found the same doorway node


def test_mount_and_stamp_order() -> None:
    pose = Pose2D(1.0, 2.0, math.pi / 2, stamp=3.0)
    assert compose(pose, (0.3, 0.1, math.pi / 2)) == pytest.approx(np.array([0.9, 2.3, math.pi]))
    model = PlaceModel.load(default_model_path())
    p = Pipeline(model, PipelineParams(mount=(0.3, 0.0, 0.0)))
    s = LaserScan(10.0, 1, "laser", 0.0, 2 * math.pi / 360, 30.0, np.full(360, 3.0, dtype=np.float32))
    r = p.process(s, Pose2D(0.0, 0.0, 0.0, stamp=10.0))
    assert (r.pose.x, r.pose.y) == pytest.approx((0.3, 0.0))
    assert p.graph.nodes[r.node or 0].x == pytest.approx(0.3)  # nodes are at the laser's position
    with pytest.raises(ValueError, match="back in time"):
        p.process(
            LaserScan(9.0, 2, "laser", 0.0, 2 * math.pi / 360, 30.0, s.ranges), Pose2D(0, 0, 0, stamp=9.0)
        )
    with pytest.raises(ValueError, match="mount"):
        PipelineParams(mount=(0.0, math.nan, 0.0))


def test_people_come_with_every_step_and_the_parameters_round_trip() -> None:
    """A person walks across a round room, 0.15 m per scan, 1.5 m ahead of a 360° laser:
    detected, tracked in the odometry frame, and once the track has walked ``min_travel``
    masked from the classifier's scan (which then equals the empty room's)."""
    from knowledge.errors import ConfigError
    from knowledge.people.pipeline import PeopleFrame
    from sim.lms_world import ray_circle_ranges

    model = PlaceModel.load(default_model_path())
    n, inc = 720, math.pi / 360
    angles = inc * np.arange(n)
    room = np.full(n, 4.0)
    with_people = Pipeline(model)
    without = Pipeline(model, PipelineParams(people=PeopleParams(enabled=False)))
    empty = Pipeline(model, PipelineParams(people=PeopleParams(enabled=False)))
    masked_at = []
    for k in range(14):
        t = 100.0 + 0.1 * k
        legs = np.array([[1.5, 0.12], [1.55, -0.12]]) + np.array([0.0, 0.15 * k - 1.0])
        seen = np.minimum(room, ray_circle_ranges((0.0, 0.0), angles, legs, np.full(2, 0.06)))
        odom = Pose2D(2.0, 1.0, math.pi / 2, stamp=t)  # the laser looks along +y of the odometry frame
        r = with_people.process(LaserScan(t, k, "laser", 0.0, inc, 30.0, seen.astype(np.float32)), odom)
        b = without.process(LaserScan(t, k, "laser", 0.0, inc, 30.0, seen.astype(np.float32)), odom)
        e = empty.process(LaserScan(t, k, "laser", 0.0, inc, 30.0, room.astype(np.float32)), odom)
        masked_at.append(r.masked is not None)
    # masked from the scan on which the track had walked 1 m (confirmed after 3 scans)
    assert masked_at[:5] == [False] * 5 and all(masked_at[-4:])
    assert b.people is None and b.masked is None
    assert isinstance(r.people, PeopleFrame) and r.masked is not None
    hit = seen < room - 0.05
    assert np.array_equal(r.masked, hit)
    assert np.abs(r.ranges - e.ranges).max() < 0.05  # the classifier saw the empty room
    assert np.abs(b.ranges - e.ranges).max() > 1.0  # without masking it saw the legs
    assert len(r.people.people) == 1
    x, y = r.people.people.positions[0]
    assert (x, y) == pytest.approx((2.0 - 0.95, 2.5), abs=0.1)  # 1.5 m ahead of the laser, odometry frame
    SCHEMAS.validate(r.people.to_json("odom"))
    # parameters: in the recordings' table, and old tables (before people) mean people off
    params = PipelineParams(people=PeopleParams(mask=False, doorways="unknown"))
    assert PipelineParams.from_table(params.to_table()) == params
    old = {k: v for k, v in PipelineParams().to_table().items() if k != "people"}
    assert PipelineParams.from_table(old).people.enabled is False
    with pytest.raises(ConfigError, match="doorways"):
        PipelineParams.from_table({"people": {"doorways": "sometimes"}})
    with pytest.raises(ValueError, match="margin"):
        PeopleParams(margin=-1)


def test_the_hmm_filters_the_labels_and_both_histograms_are_published(
    model: PlaceModel, drive: Drive
) -> None:
    """With a model that carries an HMM (Sect. 5.4) the label comes from the filtered belief;
    the raw histogram is still there, equal to a pipeline's without the HMM."""
    from agent.core.pipeline import PlaceFilterParams
    from knowledge.errors import ConfigError
    from knowledge.learning.hmm import PlaceHMM

    K = len(model.classes)
    means = np.full((K, K), 0.1 / (K - 1)) + np.eye(K) * (0.9 - 0.1 / (K - 1))
    counts = np.eye(K) * 500 + 10
    hmm = PlaceHMM(m=None).fit(means, np.array(model.classes), classes=model.classes, move_counts=counts)
    with_hmm = model.with_hmm(hmm)
    laser_scans = scans(drive, "front")
    off = PipelineParams(people=PeopleParams(enabled=False))
    plain = Pipeline(
        with_hmm, PipelineParams(people=PeopleParams(enabled=False), places=PlaceFilterParams(hmm=False))
    )
    filtered = Pipeline(with_hmm, off)
    raw_vote = Pipeline(
        with_hmm, PipelineParams(people=PeopleParams(enabled=False), places=PlaceFilterParams(vote="raw"))
    )
    a, b, c = [], [], []
    for i in range(len(laser_scans)):
        odom = Pose2D(*map(float, drive.poses[i]), stamp=laser_scans[i].stamp)
        a.append(plain.process(laser_scans[i], odom))
        b.append(filtered.process(laser_scans[i], odom))
        c.append(raw_vote.process(laser_scans[i], odom))
    assert all(r.filtered is None for r in a) and all(r.filtered is not None for r in b)
    min_coverage = filtered.graph.params.min_coverage
    observed, previous, skipped = False, None, 0
    for x, y, z in zip(a, b, c, strict=True):
        assert y.raw_probabilities == pytest.approx(x.probabilities)
        assert y.filtered is not None and sum(y.filtered.values()) == pytest.approx(1.0)
        if y.coverage < min_coverage:
            # a scan that does not vote is no observation: the belief stays as it was
            skipped += 1
            if previous is None:
                assert y.filtered == pytest.approx(dict.fromkeys(model.classes, 1 / K))
            else:
                assert y.filtered == pytest.approx(previous)
        observed = observed or y.coverage >= min_coverage
        if observed:
            assert y.label == max(y.filtered, key=lambda k: y.filtered[k])  # type: ignore[index]
        else:  # before the first observation the label is the histogram's own
            assert y.label == y.raw_label
        assert z.label == x.label == y.raw_label  # vote = "raw" publishes the raw label
        previous = y.filtered
    assert skipped > 0 and observed  # the front laser's first scans are half interpolated
    # filtering removes flickering: fewer label changes along the drive
    flips = [sum(p.label != q.label for p, q in itertools.pairwise(rs)) for rs in (a, b)]
    assert flips[1] <= flips[0]
    message = place_message(b[-1])
    SCHEMAS.validate(message, "loci.place/1")
    assert message["filtered_probabilities"] == pytest.approx(b[-1].filtered)
    assert message["raw_probabilities"] == pytest.approx(a[-1].probabilities)
    assert place_message(a[-1])["filtered_probabilities"] is None
    SCHEMAS.validate(place_message(a[-1]), "loci.place/1")
    # parameters round-trip; a recording's table from before the filter means no filter
    params = PipelineParams(places=PlaceFilterParams(vote="raw"))
    assert PipelineParams.from_table(params.to_table()) == params
    old = {k: v for k, v in PipelineParams().to_table().items() if k != "places"}
    assert PipelineParams.from_table(old).places.hmm is False
    with pytest.raises(ConfigError, match="vote"):
        PipelineParams.from_table({"places": {"vote": "loudest"}})


def test_scans_left_out_by_max_rate_still_feed_the_local_map_and_the_doorways(
    model: PlaceModel, drive: Drive
) -> None:
    """``[laser] max_rate``: only every third scan is processed; the others go through
    ``observe`` (people, local map, doorway detector). The door is found, and a doorway the
    detector reports on an observed scan enters the graph with the next processed one."""
    laser_scans = scans(drive, "front")
    pipeline = Pipeline(model, PipelineParams())
    reported: list[tuple[float, bool]] = []
    update = pipeline.detector.update

    def spy(points: np.ndarray, pose: np.ndarray, stamp: float = 0.0) -> object:
        found = update(points, pose, stamp)
        if found is not None:
            reported.append((stamp, stamp in observed))
        return found

    pipeline.detector.update = spy  # type: ignore[method-assign]
    observed: set[float] = set()
    for i, s in enumerate(laser_scans):
        x, y, th = drive.poses[i]
        pose = Pose2D(x, y, th, stamp=s.stamp)
        if i % 3:
            observed.add(s.stamp)
            pipeline.observe(s, pose)
        else:
            pipeline.process(s, pose)
    assert pipeline.scans + pipeline.observed == len(laser_scans) and pipeline.observed == len(observed)
    doors = pipeline.graph.doorway_nodes()
    assert len(doors) == 1
    assert math.hypot(doors[0].x - drive.door.center[0], doors[0].y - drive.door.center[1]) < 0.5
    # the door was passed twice; at least one passage was reported on an observed scan
    assert len(reported) == 2 and any(on_observed for _, on_observed in reported), reported
    with pytest.raises(ValueError, match="back in time"):
        pipeline.observe(laser_scans[0], Pose2D(0.0, 0.0, 0.0, stamp=laser_scans[0].stamp))
