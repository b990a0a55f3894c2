"""People tracks over a recording and their CLEAR-MOT scores against a benchmark bag's
annotations: bags written by the rosbags writer (a robot driving past a walking person,
annotated as the leg_tracker benchmark's tool does), the tracks file, the scoring rules
(laser frame per scan, the arc, the window, annotated scans the tracker never got), the CLI
as a user types it, and the real benchmark bag (data marker)."""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg
from support.bags import Bag
from support.cli import loci

from agent.people_tracks import (
    TrackFrame,
    TrackRun,
    bag_examples,
    bag_segments,
    read_annotations,
    read_tracks,
    recording_scans,
    score_tracks,
    track_recording,
    track_scans,
    write_tracks,
)
from agent.recording.importer import import_log
from knowledge.errors import DataError
from knowledge.metric.grid import OccupancyGrid
from knowledge.people.pipeline import PeoplePipeline
from sim.lms_world import LmsWorld
from sim.people import SimPerson

REPO = Path(__file__).resolve().parents[2]
T0 = 1_403_024_474.0
N_BEAMS, INC, AMIN, RMAX = 768, 0.006135923322290182, -2.356194496154785, 11.0
PERSON = "geometry_msgs/Pose pose\nuint32 id\n"  # leg_tracker/Person, as in the benchmark bag
RATE = 7.5
MOUNT = (0.3, 0.1, 0.2)  # the laser on the base: x, y, yaw


def compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


def in_laser(laser: tuple[float, float, float], p: tuple[float, float]) -> tuple[float, float]:
    c, s = math.cos(laser[2]), math.sin(laser[2])
    dx, dy = p[0] - laser[0], p[1] - laser[1]
    return (c * dx + s * dy, -s * dx + c * dy)


class BenchmarkBag(Bag):
    """A ROS 1 bag with the benchmark's annotation topic."""

    def __init__(self, path: Path) -> None:
        super().__init__(path, "ros1")
        self.store.register(get_types_from_msg(PERSON, "leg_tracker/msg/Person"))

    def annotate(self, person_id: int, xy: tuple[float, float], log_time: float) -> None:
        t = self.t
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=xy[0], y=xy[1], z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        msg = t["leg_tracker/msg/Person"](pose=pose, id=person_id)
        self.write("/ground_truth_people_tracks", "leg_tracker/msg/Person", msg, log_time)

    def odom_at(self, stamp: float, x: float, y: float, yaw: float) -> None:
        # Bag.odometry puts the robot at y = 0.5 and takes x and yaw
        assert y == 0.5
        self.odometry(stamp, x=x, yaw=yaw)


def write_walk_bag(path: Path, seconds: float = 7.0) -> tuple[Path, int]:
    """A robot driving at 0.4 m/s down a 12 m hall while a person walks across ahead of it;
    every scan's person annotated in the laser's frame (from the scan's bag time to the next,
    at the midpoint, as the benchmark's tool writes them). Returns the path and the number of
    annotations written."""
    occ = np.zeros((160, 260), dtype=bool)  # 13 m × 8 m at 5 cm
    occ[:3] = occ[-3:] = True
    occ[:, :3] = occ[:, -3:] = True
    grid = OccupancyGrid.from_masks(occ, 0.05)
    walker = SimPerson([(6.0, 7.0), (6.5, 1.0)], 0.9)

    def base(t: float) -> tuple[float, float, float]:
        return (1.0 + 0.4 * t, 0.5, 0.0)

    def laser(t: float) -> tuple[float, float, float]:
        return compose(base(t), MOUNT)

    # the world is shifted so that the robot's odometry (y = 0.5) runs along the hall's middle
    shift = np.array([0.0, 3.5])

    def world_pose(t: float) -> tuple[float, float, float]:
        x, y, th = laser(t)
        return (x + shift[0], y + shift[1], th)

    world = LmsWorld(grid, world_pose, list(walker.legs()), noise_std=0.005, seed=3)
    bag = BenchmarkBag(path)
    bag.tf(
        "/tf_static", [bag.transform("base_link", "left_laser", (MOUNT[0], MOUNT[1], 0.0), yaw=MOUNT[2])], T0
    )
    n_scans = int(seconds * RATE)
    annotations = 0
    for i in range(int(seconds * 30) + 3):
        t = i / 30
        b = base(t)
        bag.odom_at(T0 + t, b[0], b[1], b[2])
    for k in range(n_scans):
        t = k / RATE
        r = world.ranges(t, n_beams=N_BEAMS, fov=INC * (N_BEAMS - 1), max_range=RMAX, angle_min=AMIN)
        bag.scan(T0 + t, list(r), inc=INC, start=AMIN, frame="left_laser")
        log = T0 + t + 0.01  # Bag.scan's log time
        body = np.array(walker.position(t)) - shift
        rel = in_laser(laser(t), (float(body[0]), float(body[1])))
        if k < n_scans - 1 and math.hypot(*rel) < 6.0:
            bag.annotate(7, rel, log + 0.5 / RATE)
            annotations += 1
    bag.close()
    return path, annotations


@pytest.fixture(scope="module")
def walk_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    return write_walk_bag(tmp_path_factory.mktemp("bag") / "walk.bag")


def test_annotations_belong_to_the_scan_before_them(walk_bag: tuple[Path, int]) -> None:
    path, n = walk_bag
    ann = read_annotations(path)
    assert len(ann) == n > 20
    assert ann.frame_id == "left_laser" and ann.before_first_scan == 0
    assert ann.scan_stamps.size == int(7.0 * RATE)
    # each annotation is named by the header stamp of the scan written just before it
    assert set(np.round(ann.stamp - T0, 6)) <= set(np.round(ann.scan_stamps - T0, 6))
    ids, pos = ann.at(float(ann.stamp[0]))
    assert ids.tolist() == [7] and pos.shape == (1, 2)


def test_a_bag_without_annotations_is_a_clear_error(tmp_path: Path) -> None:
    bag = Bag(tmp_path / "plain.bag", "ros1")
    bag.scan(T0, [1.0, 2.0, 3.0])
    bag.close()
    with pytest.raises(DataError, match="ground_truth_people_tracks"):
        read_annotations(tmp_path / "plain.bag")
    (tmp_path / "junk.bag").write_bytes(b"not a bag")
    with pytest.raises(DataError, match="cannot open"):
        read_annotations(tmp_path / "junk.bag")


def frame(
    stamp: float, pose: tuple[float, float, float], tracks: list[tuple[int, float, float, int]]
) -> TrackFrame:
    t = np.array([(i, x, y, m, 0.0) for i, x, y, m in tracks], dtype=np.float64).reshape(-1, 5)
    return TrackFrame(stamp, pose, t[:, 1:3].copy(), t)


def test_tracks_are_scored_in_the_lasers_frame_within_the_arc_and_the_window(
    walk_bag: tuple[Path, int],
) -> None:
    ann = read_annotations(walk_bag[0])
    stamps = [float(s) for s in np.unique(ann.stamp)][:6]
    pose = (10.0, -2.0, math.pi / 2)  # the laser in the odometry frame

    def odom(p: np.ndarray) -> tuple[float, float]:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return (pose[0] + c * p[0] - s * p[1], pose[1] + s * p[0] + c * p[1])

    frames = []
    for k, st in enumerate(stamps):
        _, p = ann.at(st)
        x, y = odom(p[0] + [0.1, 0.0])
        tracks = [(1, x, y, 0)]
        if k == 2:
            tracks.append((2, *odom(np.array([0.0, -3.0])), 0))  # behind the arc (-90°): not scored
            tracks.append((3, *odom(np.array([2.0, -0.5])), 0))  # in the arc, nobody there
        if k == 3:
            tracks[0] = (1, x, y, 2)  # coasting: scored only with coasting=True
        frames.append(frame(st, pose, tracks))
    del frames[4]  # an annotated scan the tracker never got: its person is missed
    t0 = float(ann.scan_stamps[0])
    window = (stamps[0] - t0 - 1e-3, stamps[5] - t0 + 1e-3)
    res = score_tracks(frames, ann, window=window, arc_deg=(-80.0, 80.0))
    m = res.mot
    assert (m.objects, m.valid, m.misses, m.false_positives, m.id_switches) == (6, 4, 2, 1, 0)
    assert m.motp == pytest.approx(0.1)
    assert res.annotated_scans_missing == 1 and res.frames == 6
    coast = score_tracks(frames, ann, window=window, arc_deg=(-80.0, 80.0), coasting=True).mot
    assert (coast.valid, coast.misses) == (5, 1)
    # the window: only the first two scans
    early = score_tracks(frames, ann, window=(-1.0, stamps[1] - t0 + 1e-3), arc_deg=None).mot
    assert (early.objects, early.valid) == (2, 2)
    with pytest.raises(DataError, match="window"):
        score_tracks(frames, ann, window=(1e6, 2e6))


def test_the_tracks_file_round_trips_and_bad_lines_are_named(tmp_path: Path) -> None:
    run = TrackRun(frames=[frame(1.0, (0.0, 0.0, 0.1), [(3, 1.0, 2.0, 0)]), frame(1.1, (0.1, 0.0, 0.1), [])])
    p = tmp_path / "t.jsonl"
    write_tracks(p, run, {"recording": "x"})
    header, frames = read_tracks(p)
    assert header["recording"] == "x" and header["run"]["processed"] == 2
    assert frames[0].tracks.tolist() == [[3.0, 1.0, 2.0, 0.0, 0.0]] and frames[1].tracks.shape == (0, 5)
    lines = p.read_text().splitlines()
    p.write_text("\n".join([*lines, '{"stamp": 1.2, "sensor_pose": [0, 0]}']) + "\n")
    with pytest.raises(DataError, match=r":4: not a track frame"):
        read_tracks(p)
    p.write_text("\n".join([lines[0], lines[2], lines[1]]) + "\n")
    with pytest.raises(DataError, match="increase"):
        read_tracks(p)
    p.write_text('{"schema": "something/1"}\n')
    with pytest.raises(DataError, match="loci people track"):
        read_tracks(p)


@pytest.mark.slow
def test_track_and_evaluate_a_bag_from_the_command_line(walk_bag: tuple[Path, int], tmp_path: Path) -> None:
    """loci people track BAG → tracks.jsonl → loci people evaluate-tracks: the walker is
    tracked, in the odometry frame of a moving robot, and scored in the laser's frame."""
    path, n = walk_bag
    out = tmp_path / "tracks.jsonl"
    proc = loci("people", "track", path, "--out", out, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["processed"] == summary["scans"] == int(7.0 * RATE) and summary["tracks"] >= 1
    assert summary["mount"] == pytest.approx(list(MOUNT), abs=1e-6)
    proc = loci("people", "evaluate-tracks", out, "--truth", path, "--json", "--all-bearings")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    m = res["clear_mot"]
    assert m["objects"] == n
    assert m["valid"] >= 0.6 * n  # the walker is tracked once confirmed
    assert m["false_positives"] <= 2 and m["id_switches"] == 0
    assert m["motp_m"] < 0.15
    text = loci("people", "evaluate-tracks", out, "--truth", path, "--all-bearings")
    assert "MOTA" in text.stdout and "precision" in text.stdout
    bad = loci("people", "evaluate-tracks", out, "--truth", tmp_path / "missing.bag")
    assert bad.returncode != 0 and "missing.bag" in bad.stderr


@pytest.mark.slow
def test_track_takes_the_protocols_options(walk_bag: tuple[Path, int], tmp_path: Path) -> None:
    """loci people track --min-score/--min-travel/--min-seen-through run the protocol's choice;
    the tracks file's header records them; --plain takes none; a bad value is an error."""
    path, _ = walk_bag
    out = tmp_path / "tracks.jsonl"
    proc = loci(
        "people", "track", path, "--out", out, "--json",
        "--min-score", "0.4", "--min-travel", "0.1", "--min-seen-through", "2",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    header, frames = read_tracks(out)
    assert header["options"] == {"min-score": 0.4, "min-travel": 0.1, "min-seen-through": 2}
    assert header["command"].endswith("--min-score 0.4 --min-travel 0.1 --min-seen-through 2")
    assert len(frames) == int(7.0 * RATE) and any(len(f.tracks) for f in frames)  # the walker moves
    bad = loci("people", "track", path, "--out", out, "--plain", "--min-score", "0.4")
    assert bad.returncode != 0 and "--plain takes none of --min-score" in bad.stderr
    bad = loci("people", "track", path, "--out", out, "--min-travel", "-1")
    assert bad.returncode != 0 and "min_travel" in bad.stderr


def test_scans_read_once_track_as_the_recording_does(walk_bag: tuple[Path, int], tmp_path: Path) -> None:
    """An evaluation reads a recording once (recording_scans) and tracks it many times
    (track_scans): the same frames and accounting as track_recording, every time."""
    path, _ = walk_bag
    rec = tmp_path / "walk.mcap"
    import_log(path, rec, fmt="ros1")
    direct = track_recording(rec, PeoplePipeline())
    acc = TrackRun()
    scans = list(recording_scans(rec, acc))
    assert acc.scans == len(scans) == int(7.0 * RATE) and acc.odometry > 0
    for _ in range(2):
        again = track_scans(scans, PeoplePipeline(), TrackRun(**{**acc.__dict__, "frames": []}))
        assert again.summary() | {"people_seconds": 0} == direct.summary() | {"people_seconds": 0}
        assert [f.to_json() for f in again.frames] == [f.to_json() for f in direct.frames]
    assert any(len(f.tracks) for f in direct.frames)


def test_bag_segments_are_cut_by_time_as_bag_examples(walk_bag: tuple[Path, int]) -> None:
    """One read of the bag (bag_segments, with each segment's time) gives the same training
    examples for a window as bag_examples, and the two halves add up to the whole."""
    path, _ = walk_bag
    X, y, dist, t, scan_t = bag_segments(path)
    assert scan_t.size == int(7.0 * RATE) and t.shape == y.shape == dist.shape and X.shape[0] == y.size
    assert y.any() and (~y).any()
    halves = [bag_examples(path, window=w) for w in ((-math.inf, 3.0), (3.0, math.inf))]
    for (Xh, yh, _, counts), sel in zip(halves, (t < 3.0, t >= 3.0), strict=True):
        assert np.array_equal(Xh, X[sel]) and np.array_equal(yh, y[sel])
        assert counts["people"] == int(y[sel].sum())
    assert sum(h[3]["scans"] for h in halves) == scan_t.size
    with pytest.raises(DataError, match="no scan in the window"):
        bag_examples(path, window=(100.0, 200.0))


@pytest.mark.data
@pytest.mark.slow
def test_the_benchmark_bag(shared_data: Path, tmp_path: Path) -> None:
    """The leg_tracker benchmark's annotated "Moving" bag: 873 scans, 153 annotations (133
    in the scorer's arc); the agent's tracker against the published joint-leg tracker's
    MOTA 10.2 % and MOTP 0.15 m (docs/results/people_tracks.md)."""
    src = shared_data / "people" / "general_tracking_moving_1.bag.zip"
    if not src.is_file():
        pytest.skip(f"{src} is absent")
    with zipfile.ZipFile(src) as z:
        z.extractall(tmp_path)
    bag = tmp_path / "general_tracking_moving_1.bag"
    out = tmp_path / "tracks.jsonl"
    proc = loci("people", "track", bag, "--out", out, "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["processed"] == 873
    res = json.loads(loci("people", "evaluate-tracks", out, "--truth", bag, "--json").stdout)
    m = res["clear_mot"]
    assert res["annotations"] == 153 and m["objects"] == 133 and m["frames"] == 873
    print(m)
    assert m["mota_pct"] > 10.2 and m["motp_m"] < 0.15
