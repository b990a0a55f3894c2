"""``loci replay`` on MCAP files written here with the recorder's sink.

A recording holds a scripted drive along a generated office's corridor: 360° scans ray cast
at 10 Hz and odometry at 50 Hz whose samples include each scan's stamp, so the pose each
scan must get is known without any interpolation. The expected map is the pipeline fed
those (scan, pose) pairs directly.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy import ndimage
from support.recordings import ROBOT, T0, Run, expected, loci, make_run, write_recording

from agent.bus.bridge import RawSample
from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC
from agent.bus.schemas import SCHEMAS
from agent.core.odom_sync import SyncParams
from agent.core.pipeline import Pipeline, PipelineParams, areas_message, graph_message
from agent.recording.offline import read_recording_metadata, replay_recording
from agent.recording.recorder import McapSink, recording_metadata
from agent.recording.replay import McapMessages
from drivers.messages import Pose2D
from knowledge.labels import CLASS_CODES, read_label_image
from knowledge.metric.grid import OccupancyGrid
from knowledge.navigation.graph import GraphParams
from knowledge.places.model import PlaceModel, default_model_path
from knowledge.topology import persistence
from sim.buildings import generate_building


@pytest.fixture(scope="module")
def model() -> PlaceModel:
    return PlaceModel.load(default_model_path())


@pytest.fixture(scope="module")
def run() -> Run:
    return make_run()


@pytest.mark.slow
def test_loci_replay_rebuilds_the_map_and_writes_it(tmp_path: Path, run: Run, model: PlaceModel) -> None:
    rec = tmp_path / "run.mcap"
    write_recording(rec, run, garbage=True)  # as `loci record` writes it: no agent metadata
    want = expected(model, run)
    assert len(want.graph) >= 4
    doc = want.state_document()
    out = loci("replay", str(rec), "--out-dir", str(tmp_path / "out"), "--places", str(tmp_path / "p.jsonl"))
    assert out.returncode == 0, out.stderr
    n = len(run.scans)
    assert f"{n} scans = {n} processed + 0 dropped;" in out.stdout, out.stdout
    assert f"{len(run.poses) + 1} odometry messages (1 invalid ignored)" in out.stdout, out.stdout
    # every place message, one per line, with its stamp and the laser's pose
    lines = (tmp_path / "p.jsonl").read_text().splitlines()
    assert lines == (tmp_path / "out" / "places.jsonl").read_text().splitlines()
    places = [SCHEMAS.decode(line.encode(), "loci.place/1") for line in lines]
    assert [p["stamp"] for p in places] == [s.stamp for s in run.scans]
    assert [p["pose"]["x"] for p in places] == pytest.approx([p.x for p in run.scan_poses], abs=1e-4)
    picture = cv2.imread(str(tmp_path / "out" / "map.png"))
    assert picture is not None and picture.shape[0] > 100 and picture.shape[1] > 100
    graph = json.loads((tmp_path / "out" / "graph.json").read_text())
    areas = json.loads((tmp_path / "out" / "areas.json").read_text())
    assert graph == graph_message(doc, run.scans[-1].stamp)
    assert areas == areas_message(doc, run.scans[-1].stamp)
    g, a = persistence.load(tmp_path / "out" / "navgraph.json")
    assert sorted(g.nodes) == sorted(want.graph.nodes) and a is not None
    assert {k: n.label for k, n in g.nodes.items()} == {k: n.label for k, n in want.graph.nodes.items()}


@pytest.mark.slow
def test_loci_replay_saves_the_map_it_built_for_map_server_and_loci_localize(
    tmp_path: Path, run: Run
) -> None:
    """--out-dir writes the occupancy map as map_server YAML + PGM and its label image; loaded
    back, its walls and free space lie where the building's are, its labels are the graph's,
    and ``loci localize`` tracks the recording in it."""
    rec = tmp_path / "run.mcap"
    write_recording(rec, run)
    out = tmp_path / "out"
    done = loci("replay", rec, "--out-dir", out)
    assert done.returncode == 0, done.stderr
    assert "map.yaml + map.pgm (the occupancy map, frame odom), labels.png + labels.yaml" in done.stdout
    meta = yaml.safe_load((out / "map.yaml").read_text())
    assert meta["image"] == "map.pgm" and meta["resolution"] == 0.05 and len(meta["origin"]) == 3
    assert (out / "map.pgm").read_bytes().startswith(b"P5")  # binary PGM, as map_saver writes
    grid = OccupancyGrid.load(out / "map.yaml")
    truth = generate_building(3, furniture=False, layout="straight").grid  # the world make_run drove
    # every wall cell of the map is on a wall of the building (within 2 cells, 10 cm) ...
    walls = ndimage.binary_dilation(truth.occupied, iterations=2)
    cells = truth.world_to_cell(grid.cell_to_world(np.argwhere(grid.occupied)))
    assert len(cells) > 500 and truth.in_bounds(cells).all()
    assert walls[cells[:, 0], cells[:, 1]].mean() > 0.98
    # ... every free cell in the building's free space (within a cell) ...
    space = ndimage.binary_dilation(truth.free, iterations=1)
    cells = truth.world_to_cell(grid.cell_to_world(np.argwhere(grid.free)))
    assert len(cells) > 20_000 and space[cells[:, 0], cells[:, 1]].mean() > 0.99
    # ... the corridor the robot drove is free, and its two walls beside the drive are in the map
    path = np.array([(p.x, p.y) for p in run.scan_poses])
    on_path = grid.world_to_cell(path)
    assert grid.free[on_path[:, 0], on_path[:, 1]].all()
    _, y0, _, y1 = generate_building(3, furniture=False, layout="straight").corridors[0].rects[0]
    near = ndimage.binary_dilation(grid.occupied, iterations=2)
    for wall_y in (y0 - 0.5 * truth.resolution, y1 + 0.5 * truth.resolution):
        xs = np.arange(path[0, 0], path[-1, 0], 0.05)
        points = np.stack([xs, np.full_like(xs, wall_y)], axis=1)
        t = truth.world_to_cell(points)
        solid = points[truth.occupied[t[:, 0], t[:, 1]]]  # the wall, not its doors
        c = grid.world_to_cell(solid)
        assert len(solid) > 40 and near[c[:, 0], c[:, 1]].mean() > 0.95, wall_y
    # the label image: one code per map cell, labels only on free cells (all but cells no free
    # path joins to the drive), each node's own label at its cell
    codes = read_label_image(out / "labels.png")
    assert codes.shape == grid.shape and not codes[~grid.free].any()
    assert (codes[grid.free] > 0).mean() > 0.999
    graph = json.loads((out / "graph.json").read_text())
    at = grid.world_to_cell(np.array([(n["x"], n["y"]) for n in graph["nodes"]]))
    assert [int(codes[r, c]) for r, c in at] == [CLASS_CODES[n["label"]] for n in graph["nodes"]]
    assert yaml.safe_load((out / "labels.yaml").read_text())["origin"] == meta["origin"]
    # loci localize tracks the run in the saved map, labels included
    start, end = run.scan_poses[0], run.scan_poses[-1]
    done = loci(
        "localize", out / "map.yaml", "--recording", rec, "--labels", out / "labels.png",
        "--initial", start.x, start.y, 0, "--particles", 500, "--json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    s = json.loads(done.stdout)
    assert s["mode"] == "tracking" and s["semantic"] is True and s["updates"] > 20
    assert math.hypot(s["pose"]["x"] - end.x, s["pose"]["y"] - end.y) < 0.2, s["pose"]


@pytest.mark.slow
def test_a_truncated_recording_replays_up_to_its_last_complete_message(
    tmp_path: Path, run: Run, model: PlaceModel
) -> None:
    rec = tmp_path / "run.mcap"
    write_recording(rec, run)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(rec.read_bytes()[: int(rec.stat().st_size * 0.6)])  # a crashed writer's file
    kept = McapMessages(cut)
    scans = [m for m in kept if m.topic.endswith("/scan")]
    assert kept.truncated and 0 < len(scans) < len(run.scans)
    out = loci("replay", str(cut), "--json")
    assert out.returncode == 0, out.stderr
    assert "ends without its footer" in out.stderr
    got = json.loads(out.stdout)
    assert got["truncated"]
    # the scans whose odometry made it into the file, or that are at most max_extrapolation past
    # it, are processed; the others wait in vain
    last_odom = max(POSE_CODEC.decode(m.data).stamp for m in kept.__class__(cut) if m.topic.endswith("/odom"))
    n = sum(LASER_SCAN_CODEC.decode(m.data).stamp <= last_odom + 0.1 for m in scans)
    assert got["stats"]["accounting"] == {
        "scans": len(scans),
        "processed": n,
        "failed": 0,
        "dropped": {"unfinished": len(scans) - n} if len(scans) > n else {},
        "invalid": 0,
        "skipped": 0,
        "over_rate": 0,
        "balanced": True,
    }
    assert got["stats"]["processed"] == n
    want = expected(model, run, n=n)
    assert got["graph"]["nodes"] == graph_message(want.state_document(), 0.0)["nodes"]


def test_recorded_parameters_initial_map_and_live_end_are_used(
    tmp_path: Path, run: Run, model: PlaceModel
) -> None:
    half = len(run.scans) // 2
    params = PipelineParams(graph=GraphParams(node_distance=1.6, window=5))
    first = expected(model, run, params, n=half)
    initial = persistence.dumps(first.state_document())
    rec = tmp_path / "resumed.mcap"
    meta = recording_metadata(
        ROBOT,
        pipeline=json.dumps(params.to_table()),
        model=str(default_model_path()),
        initial_state=initial,
        max_wait=0.2,
        max_gap=0.5,
    )
    later = Run(
        run.scans[half:], [p for p in run.poses if p.stamp >= run.scans[half].stamp], run.scan_poses[half:]
    )
    write_recording(rec, later, metadata=meta)
    assert read_recording_metadata(rec)["initial_state"] == initial
    res = replay_recording(rec, model=model)
    want = Pipeline.from_state(json.loads(initial), model, params)
    for scan, pose in zip(later.scans, later.scan_poses, strict=True):
        want.process(scan, pose)
    assert res.resumed and res.pipeline.params.graph.node_distance == 1.6
    got, exp = res.pipeline.state_document(), want.state_document()
    assert got["nodes"] == exp["nodes"] and got["areas"] == exp["areas"]
    assert min(set(res.pipeline.graph.nodes) - set(first.graph.nodes)) >= first.graph.next_id
    fresh = replay_recording(rec, model=model, fresh=True)
    assert not fresh.resumed and min(fresh.pipeline.graph.nodes) == 1


def test_realtime_replay_keeps_the_recorded_pace(tmp_path: Path, run: Run, model: PlaceModel) -> None:
    rec = tmp_path / "short.mcap"
    write_recording(rec, run, until=T0 + 1.0)
    t = time.monotonic()
    fast = replay_recording(rec, model=model)
    fast_s = time.monotonic() - t
    t = time.monotonic()
    paced = replay_recording(rec, model=model, speed=1.0)
    paced_s = time.monotonic() - t
    assert paced.pipeline.scans == fast.pipeline.scans > 0
    assert paced_s >= 0.9 and paced_s > fast_s


@pytest.mark.slow
def test_errors_say_what_is_wrong(tmp_path: Path) -> None:
    out = loci("replay", str(tmp_path / "absent.mcap"))
    assert out.returncode == 2 and "no such recording" in out.stderr
    empty = tmp_path / "empty.mcap"
    with McapSink(empty) as sink:
        sink.write(
            RawSample(
                "loci/rosie/odom", POSE_CODEC.encode(Pose2D(0, 0, 0, stamp=T0)), POSE_CODEC.zenoh_encoding, 1
            )
        )
    with pytest.raises(Exception, match="no loci/rosie/scan messages"):
        replay_recording(empty, robot="rosie")
    not_mcap = tmp_path / "text.mcap"
    not_mcap.write_text("hello")
    out = loci("replay", str(not_mcap))
    assert out.returncode == 2 and "not an MCAP file" in out.stderr


def test_map_edits_that_do_not_fit_or_do_not_decode_change_nothing(
    tmp_path: Path, run: Run, model: PlaceModel
) -> None:
    """A recorded map edit naming a place node (only doorways can be removed) is counted as not
    fitting; a malformed one is left out; the map is the one the scans make."""
    rec = tmp_path / "run.mcap"
    write_recording(rec, run)
    want = expected(model, run)
    place = next(iter(want.graph.place_nodes())).id
    after = run.scans[5].stamp
    edits = [
        {"schema": "loci.map_edit/1", "op": "remove_doorway", "node": place, "after_scan": after},
        {"schema": "loci.map_edit/1", "op": "paint_it_red", "node": place, "after_scan": after},
    ]
    with McapSink(tmp_path / "edits.mcap") as sink:
        for m in McapMessages(rec):
            sink.write(RawSample(m.topic, m.data, m.zenoh_encoding, m.log_time_ns))
            if m.topic.endswith("/scan") and m.log_time_ns >= int((after + 0.008) * 1e9) and edits:
                for e in edits:
                    data = json.dumps(e).encode()
                    sink.write(
                        RawSample(f"loci/{ROBOT}/map/edit", data, "application/json", m.log_time_ns + 1)
                    )
                edits = []
    out = replay_recording(tmp_path / "edits.mcap", model=model)
    assert out.edits == 0 and out.edits_failed == 1
    assert sorted(out.pipeline.graph.nodes) == sorted(want.graph.nodes)


def test_jittered_scan_stamps_cost_no_scan_in_a_replay(tmp_path: Path, run: Run, model: PlaceModel) -> None:
    """A third of the scans are stamped up to 0.9 s early (a jittery laser clock) and arrive in
    the order they were taken; the replay of such a foreign recording holds scans 1 s, so
    every scan is processed, in stamp order, each with the pose at its own stamp."""
    rng = np.random.default_rng(5)
    early = np.where(rng.random(len(run.scans)) < 1 / 3, rng.uniform(0.0, 0.9, len(run.scans)), 0.0)
    early[:5] = 0.0  # not before the first odometry sample
    jittered = [replace(s, stamp=s.stamp - e) for s, e in zip(run.scans, early, strict=True)]
    assert sum(b.stamp < a.stamp for a, b in itertools.pairwise(jittered)) > 5
    rec = tmp_path / "jitter.mcap"
    with McapSink(rec) as sink:
        events = [(int((p.stamp + 0.003) * 1e9), "odom", POSE_CODEC.encode(p)) for p in run.poses]
        events += [  # arrival: when the scan was taken, not its stamp
            (int((s.stamp + 0.008) * 1e9), "scan", LASER_SCAN_CODEC.encode(j))
            for s, j in zip(run.scans, jittered, strict=True)
        ]
        for t, stream, data in sorted(events):
            codec = POSE_CODEC if stream == "odom" else LASER_SCAN_CODEC
            sink.write(RawSample(f"loci/{ROBOT}/{stream}", data, codec.zenoh_encoding, t))
    stamps: list[float] = []
    res = replay_recording(rec, model=model, on_step=lambda r: stamps.append(r.stamp))
    assert res.processed == len(run.scans) and res.accounting()["balanced"]
    assert stamps == sorted(j.stamp for j in jittered)
    # held 0 s (as a robot runs by default), a late scan costs itself and nothing else
    res0 = replay_recording(rec, model=model, sync=SyncParams(reorder=0.0))
    acc = res0.accounting()
    assert acc["balanced"] and set(acc["dropped"]) == {"late"}
    assert acc["processed"] + acc["dropped"]["late"] == len(run.scans)
