"""Navigation graph, doorways and areas measured in the simulator (book Sects. 3.5, 7.2.2, 7.2.3).

For each generated office (seeds the bundled place model was not trained on):

1. **Route**: from the middle of a corridor, visit ``--rooms`` rooms (halls count as rooms)
   drawn from the ``2 × --rooms`` nearest, each time going to the nearest unvisited one by
   path length. Paths are planned on a 0.1 m grid with a clearance cost, so they pass doors
   through their middle.
2. **Drive**: :class:`~drivers.sim.base.SimBase` follows the path (0.6 m/s); every 0.1 s
   the true pose, the odometry and the time are recorded. Odometry either equals the true
   pose ("exact") or drifts with SimBase's default noise ("drift").
3. **Scan**: a scan is ray cast from every true pose with 1 cm Gaussian noise: a 360° laser
   (360 beams, the model's own format) or a 180° front laser (361 beams at 0.5°, SICK LMS
   2xx) whose rear half is simulated from the local map (Sect. 3.5).
4. **Run the core pipeline** per scan as the agent does (docs/navigation.md): with the front
   laser, local map ← scan (odometry pose), full scan, doorway detector on the local map's
   points; with the 360° laser, the scan resampled and the detector on its own points; then
   the place model, the navigation graph (``update(pose, label, doorway, in_opening,
   ranges)``) and the areas. Variants switch one choice off (min resampling, a wider hit
   radius, no local map, no visibility links).
5. **Score** against the ground truth of the building:

   * *node accuracy*: a place node is right when its label is the class of the space
     (room, corridor or hall) its true position lies in; a doorway node is right when its
     true position is within 0.75 m of a true door's centre. Reported over all nodes, over
     place nodes, and with hallway counted as corridor (the book's place nodes are room
     or corridor). Nodes in a door opening that are place nodes count as wrong.
   * *doorways*: recall = true doors the robot passed through (its true position entered the
     door's opening cells) that have a doorway node; precision = doorway nodes near a true
     door.
   * *areas*: the number of areas against the number of spaces (rooms, halls, corridors)
     the robot visited, and the share of areas whose nodes all lie in one space.
   * *scan accuracy* (context): per-scan labels against the label of the cell the robot is in.

Run: ``python -m tools.evaluate_navigation --out docs/results --seeds 0,1,2,3,4,5,6,7``
(about three minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from drivers.messages import Pose2D
from drivers.sim.base import BaseStatus, ControllerParams, OdometryNoise, SimBase
from knowledge.fileio import atomic_write_text
from knowledge.metric.beams import beam_angles
from knowledge.metric.local_map import LocalMap, LocalMapParams
from knowledge.metric.raycast import cast
from knowledge.metric.rear_beams import FullScanParams, assemble_scan, full_scan
from knowledge.navigation.doorways import Doorway, DoorwayDetector, scan_points
from knowledge.navigation.graph import DOORWAY, GraphParams, NavigationGraph
from knowledge.places.model import PlaceModel, default_model_path
from knowledge.topology.areas import AreaMap
from sim.buildings import DOOR_ID_BASE, Building, generate_building
from sim.world import SimWorld

SCAN_PERIOD = 0.1
SIM_DT = 0.02
NOISE_STD = 0.01
FRONT_BEAMS = 361
DOOR_MATCH = 0.75
KIND_CLASS = {"room": "room", "hall": "hallway", "corridor": "corridor"}
MERGE2 = {"hallway": "corridor"}


# ---------------------------------------------------------------------------- route


@dataclass
class Planner:
    """Shortest paths on a coarse grid of a building, with a cost that keeps to the middle."""

    building: Building
    step: float = 0.1
    min_clearance: float = 0.3
    _rc: np.ndarray = field(init=False)
    _index: np.ndarray = field(init=False)
    _graph: csr_matrix = field(init=False)
    _clear: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        g = self.building.grid
        free = g.free
        edt = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1] * g.resolution
        k = max(1, round(self.step / g.resolution))
        rows, cols = g.shape
        rr, cc = np.mgrid[k // 2 : rows : k, k // 2 : cols : k]
        clear = edt[rr, cc]
        ok = clear >= self.min_clearance
        index = -np.ones(ok.shape, dtype=np.int64)
        index[ok] = np.arange(int(ok.sum()))
        cost = 1.0 + 6.0 * np.maximum(0.0, 1.0 - clear) ** 2
        src, dst, w = [], [], []
        R, C = ok.shape
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            rs = slice(0, R - dr)
            cs = slice(max(0, -dc), C - max(0, dc))
            rs2 = slice(dr, R)
            cs2 = slice(max(0, -dc) + dc, C - max(0, dc) + dc)
            a, b = index[rs, cs], index[rs2, cs2]
            m = (a >= 0) & (b >= 0)
            length = math.hypot(dr, dc) * self.step
            src.append(a[m])
            dst.append(b[m])
            w.append(0.5 * (cost[rs, cs][m] + cost[rs2, cs2][m]) * length)
        n = int(ok.sum())
        s, d, ww = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
        self._graph = csr_matrix(
            (np.concatenate((ww, ww)), (np.concatenate((s, d)), np.concatenate((d, s)))), (n, n)
        )
        self._rc = np.column_stack((rr[ok], cc[ok]))
        self._index = index
        self._clear = clear[ok]

    def xy(self, nodes: np.ndarray) -> np.ndarray:
        return self.building.grid.cell_to_world(self._rc[nodes])

    def node_near(self, xy: np.ndarray) -> int:
        d = np.hypot(*(self.xy(np.arange(self._rc.shape[0])) - xy).T)
        return int(np.argmin(d))

    def best_in_space(self, space_id: int) -> int | None:
        """The coarse node of a space with the most clearance (its middle)."""
        sp = self.building.spaces[self._rc[:, 0], self._rc[:, 1]]
        idx = np.flatnonzero(sp == space_id)
        if idx.size == 0:
            return None
        return int(idx[np.argmax(self._clear[idx])])

    def costs_from(self, start: int) -> np.ndarray:
        """Path cost from ``start`` to every coarse node (inf: unreachable)."""
        return np.asarray(dijkstra(self._graph, indices=start))

    def route(self, start: int, targets: list[int]) -> tuple[list[int], list[int]]:
        """Visit ``targets`` greedily (nearest next); returns the node path and the visit order."""
        path = [start]
        order: list[int] = []
        left = set(targets)
        cur = start
        while left:
            dist, pred = dijkstra(self._graph, indices=cur, return_predecessors=True)
            reach = [t for t in left if np.isfinite(dist[t])]
            if not reach:
                break
            nxt = min(reach, key=lambda t: dist[t])
            seg = [nxt]
            while seg[-1] != cur:
                seg.append(int(pred[seg[-1]]))
            path.extend(seg[::-1][1:])
            order.append(nxt)
            left.discard(nxt)
            cur = nxt
        return path, order


def plan_route(building: Building, max_rooms: int, rng: np.random.Generator) -> np.ndarray:
    """``(k, 2)`` world waypoints: from a corridor through up to ``max_rooms`` rooms/halls."""
    planner = Planner(building)
    start_space = building.corridors[0].id
    start = planner.best_in_space(start_space)
    assert start is not None, "the corridor has no cell with enough clearance"
    rooms = [r.id for r in building.rooms]
    rng.shuffle(rooms)
    targets = [t for t in (planner.best_in_space(r) for r in rooms) if t is not None]
    # the nearest rooms first keeps the route compact; cap the number of rooms
    dist = planner.costs_from(start)
    targets = sorted(targets, key=lambda t: dist[t])[: max_rooms * 2]
    rng.shuffle(targets)
    path, _ = planner.route(start, targets[:max_rooms])
    xy = planner.xy(np.asarray(path))
    # a waypoint every ~0.3 m
    keep = [0]
    for i in range(1, len(xy)):
        if math.hypot(*(xy[i] - xy[keep[-1]])) >= 0.3 or i == len(xy) - 1:
            keep.append(i)
    return np.asarray(xy[keep])


# ---------------------------------------------------------------------------- drive


@dataclass
class Drive:
    """One simulated run: per scan the time, the true pose and the odometry pose."""

    t: np.ndarray
    true: np.ndarray
    odom: np.ndarray
    collisions: int
    length: float


def drive(building: Building, waypoints: np.ndarray, *, drift: bool, seed: int) -> Drive:
    world = SimWorld(building.grid)
    d0 = waypoints[1] - waypoints[0]
    start = Pose2D(float(waypoints[0, 0]), float(waypoints[0, 1]), math.atan2(d0[1], d0[0]))
    base = SimBase(
        world,
        start,
        noise=OdometryNoise() if drift else OdometryNoise(0.0, 0.0, 0.0),
        control=ControllerParams(waypoint_tolerance=0.25),
        seed=seed,
    )
    base.follow_path([(float(x), float(y)) for x, y in waypoints[1:]], align=False)
    every = round(SCAN_PERIOD / SIM_DT)
    ts, tr, od = [], [], []
    k = 0
    collisions = 0
    limit = 3.0 * len(waypoints) * 0.3 / 0.6 + 120.0
    while base.time < limit:
        st = base.step(SIM_DT)
        k += 1
        if k % every == 0:
            ts.append(st.time)
            tr.append(st.true_pose.as_array())
            od.append(st.odom.as_array())
        if st.status is BaseStatus.COLLIDED:
            collisions += 1
            # back on track: continue with the waypoints still ahead of the robot
            here = st.true_pose.as_array()[:2]
            rest = int(np.argmin(np.hypot(*(waypoints - here).T)))
            nxt = waypoints[min(rest + 1, len(waypoints) - 1) :]
            if len(nxt) == 0 or collisions > 50:
                break
            base.follow_path([(float(x), float(y)) for x, y in nxt], align=False)
        elif st.status is BaseStatus.REACHED:
            break
    return Drive(np.asarray(ts), np.asarray(tr), np.asarray(od), collisions, base.distance)


# ---------------------------------------------------------------------------- pipeline


@dataclass
class Config:
    name: str
    laser: str  # "360" or "front"
    drift: bool
    front: str = "nearest"
    hit_radius: float = 0.075
    use_local_map: bool = True
    window: int = 10
    links: bool = True
    min_coverage: float = GraphParams.min_coverage


def _compose(true: np.ndarray, odom: np.ndarray, xy_odom: tuple[float, float]) -> np.ndarray:
    """Odometry-frame point → world, through the transform true ⊕ odom⁻¹ of one instant."""
    dx, dy = xy_odom[0] - odom[0], xy_odom[1] - odom[1]
    c, s = math.cos(odom[2]), math.sin(odom[2])
    lx, ly = c * dx + s * dy, -s * dx + c * dy  # in the robot frame
    c2, s2 = math.cos(true[2]), math.sin(true[2])
    return np.array([true[0] + c2 * lx - s2 * ly, true[1] + s2 * lx + c2 * ly])


@dataclass
class RunResult:
    graph: NavigationGraph
    areas: AreaMap
    node_world: dict[int, np.ndarray]
    scan_labels: np.ndarray
    full_scans: np.ndarray
    seconds: np.ndarray  # per scan: local map, full scan, doorway detector, graph and areas
    known: np.ndarray  # per scan: share of the full scan's beams measured or hit (not interpolated)


def run_pipeline(building: Building, run: Drive, model: PlaceModel, cfg: Config, seed: int) -> RunResult:
    rng = np.random.default_rng(seed)
    n = model.scan.n_beams
    mr = model.scan.max_range
    prm = FullScanParams(n_beams=n, max_range=mr, hit_radius=cfg.hit_radius, front=cfg.front)
    if cfg.laser == "360":
        angles = beam_angles(n)
        raw = cast(building.grid, run.true, n_beams=n, max_range=mr, noise_std=NOISE_STD, rng=rng)
    else:
        angles = beam_angles(FRONT_BEAMS, math.pi)
        raw = cast(
            building.grid,
            run.true,
            n_beams=FRONT_BEAMS,
            fov=math.pi,
            max_range=mr,
            noise_std=NOISE_STD,
            rng=rng,
        )
    lmap = LocalMap(LocalMapParams())
    det = DoorwayDetector()
    fulls = np.empty((len(run.t), n), dtype=np.float32)
    doors: list[Doorway | None] = []
    passing: list[bool] = []
    seconds = np.zeros(len(run.t))
    known = np.ones(len(run.t))  # share of the full scan's beams not interpolated
    for i in range(len(run.t)):
        t0 = time.perf_counter()
        pose = run.odom[i]
        if cfg.laser == "360":
            # a 360° laser needs no local map: resample, and find doorways in the scan itself
            fulls[i] = full_scan(raw[i], angles, range_max=mr, params=prm)
            pts = scan_points(raw[i], angles, range_max=mr)
        else:
            lmap.add(raw[i], angles, pose, stamp=float(run.t[i]), range_max=mr)
            fulls[i], known_i = assemble_scan(
                raw[i],
                angles,
                range_max=mr,
                pose=pose,
                local_map=lmap if cfg.use_local_map else None,
                params=prm,
            )
            known[i] = known_i.mean()
            pts = lmap.points_in_robot_frame(pose)
        doors.append(det.update(pts, pose, float(run.t[i])))
        passing.append(det.passing)
        seconds[i] = time.perf_counter() - t0
    proba = model.predict_proba_scans(fulls)
    labels = np.asarray(model.classes)[np.argmax(proba, axis=1)]
    graph = NavigationGraph(GraphParams(window=cfg.window, min_coverage=cfg.min_coverage))
    areas = AreaMap()
    node_world: dict[int, np.ndarray] = {}
    for i in range(len(run.t)):
        t0 = time.perf_counter()
        upd = graph.update(
            run.odom[i],
            str(labels[i]),
            doors[i],
            in_opening=passing[i],
            ranges=fulls[i] if cfg.links else None,
            coverage=float(known[i]),
        )
        if upd.changed:
            areas.update(graph)
        seconds[i] += time.perf_counter() - t0
        for k in upd.added:
            node_world[k] = _compose(run.true[i], run.odom[i], graph.nodes[k].xy)
    return RunResult(graph, areas, node_world, labels, fulls, seconds, known)


# ---------------------------------------------------------------------------- scoring


def _space_at(building: Building, xy: np.ndarray) -> int:
    """The space id at a world point (the nearest free cell's if the point is not free)."""
    g = building.grid
    rc = g.world_to_cell(xy)
    rows, cols = g.shape
    r, c = int(np.clip(rc[0], 0, rows - 1)), int(np.clip(rc[1], 0, cols - 1))
    sid = int(building.spaces[r, c])
    if sid:
        return sid
    win = building.spaces[max(0, r - 6) : r + 7, max(0, c - 6) : c + 7]
    nz = np.argwhere(win > 0)
    if nz.size == 0:
        return 0
    j = int(np.argmin(np.hypot(*(nz - [min(r, 6), min(c, 6)]).T)))
    return int(win[nz[j][0], nz[j][1]])


def _space_class(building: Building, sid: int) -> str:
    if sid >= DOOR_ID_BASE:
        return "doorway"
    if sid == 0:
        return "none"
    return KIND_CLASS[building.space(sid).kind]


def score(building: Building, run: Drive, res: RunResult, model: PlaceModel) -> dict[str, Any]:
    g = res.graph
    doors = {d.id: d for d in building.doors}
    door_xy = np.array([d.center for d in building.doors]) if doors else np.empty((0, 2))
    door_ids = np.array([d.id for d in building.doors])
    # spaces along the true path
    cells = building.grid.world_to_cell(run.true[:, :2])
    visited = building.spaces[cells[:, 0], cells[:, 1]]
    passed = {int(v) for v in np.unique(visited) if v >= DOOR_ID_BASE}
    spaces_visited = {int(v) for v in np.unique(visited) if 0 < v < DOOR_ID_BASE}
    # nodes
    place_ok = place_n = place2_ok = 0
    door_nodes_ok = 0
    matched: Counter[int] = Counter()
    node_space: dict[int, int] = {}
    confusion: Counter[tuple[str, str]] = Counter()
    for k, node in g.nodes.items():
        w = res.node_world[k]
        if node.kind == DOORWAY:
            if door_xy.shape[0]:
                d = np.hypot(*(door_xy - w).T)
                j = int(np.argmin(d))
                if d[j] <= DOOR_MATCH:
                    door_nodes_ok += 1
                    matched[int(door_ids[j])] += 1
            continue
        sid = _space_at(building, w)
        node_space[k] = sid
        truth = _space_class(building, sid)
        pred = node.label or "none"
        confusion[(truth, pred)] += 1
        place_n += 1
        place_ok += pred == truth
        place2_ok += MERGE2.get(pred, pred) == MERGE2.get(truth, truth)
    n_door_nodes = len(g.doorway_nodes())
    n_nodes = len(g)
    # scans
    truth_cells = building.labels[cells[:, 0], cells[:, 1]]
    names = {1: "room", 2: "corridor", 3: "doorway", 4: "hallway"}
    scan_truth = np.array([names.get(int(c), "none") for c in truth_cells])
    scan_ok = float(np.mean(res.scan_labels == scan_truth))
    not_door = scan_truth != "doorway"
    m2 = np.vectorize(lambda c: MERGE2.get(c, c))
    scan_ok2 = float(np.mean(m2(res.scan_labels[not_door]) == m2(scan_truth[not_door])))
    # areas
    areas = res.areas.areas
    pure = sum(1 for a in areas.values() if len({node_space.get(k, -1) for k in a.nodes}) == 1)
    areas_of_space: dict[int, set[int]] = {}
    for a in areas.values():
        for k in a.nodes:
            areas_of_space.setdefault(node_space[k], set()).add(a.id)
    spaces_split = sum(1 for sid, ids in areas_of_space.items() if 0 < sid < DOOR_ID_BASE and len(ids) > 1)
    area_right = 0
    for a in areas.values():
        spaces = Counter(node_space[k] for k in a.nodes if k in node_space)
        major = spaces.most_common(1)[0][0] if spaces else 0
        area_right += (a.label or "none") == _space_class(building, major) if major else 0
    return {
        "seed": building.seed,
        "layout": building.params["layout"],
        "route_m": round(run.length, 1),
        "scans": len(run.t),
        "collisions": run.collisions,
        "nodes": n_nodes,
        "place_nodes": place_n,
        "unlabelled": sum(1 for n in g.nodes.values() if n.kind != DOORWAY and n.label is None),
        "doorway_nodes": n_door_nodes,
        "node_correct": place_ok + door_nodes_ok,
        "node_correct2": place2_ok + door_nodes_ok,
        "place_correct": place_ok,
        "place_correct2": place2_ok,
        "doors_passed": len(passed),
        "doors_detected": len(passed & set(matched)),
        "doors_missed": sorted(passed - set(matched)),
        "doorway_nodes_true": door_nodes_ok,
        "doorway_nodes_duplicate": int(sum(v - 1 for v in matched.values() if v > 1)),
        "spaces_visited": len(spaces_visited),
        "areas": len(areas),
        "areas_pure": pure,
        "spaces_split": spaces_split,
        "areas_class_right": area_right,
        "scan_accuracy": scan_ok,
        "scan_accuracy2_no_doorway": scan_ok2,
        "confusion": {f"{t}->{p}": v for (t, p), v in sorted(confusion.items())},
        "known_beams": float(res.known.mean()),
        "core_ms_p50": float(np.median(res.seconds) * 1e3),
        "core_ms_p99": float(np.quantile(res.seconds, 0.99) * 1e3),
        "_seconds": res.seconds,
    }


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    def tot(k: str) -> int:
        return int(sum(r[k] for r in rows))

    nodes, place = tot("nodes"), tot("place_nodes")
    dn, passed = tot("doorway_nodes"), tot("doors_passed")
    scans = tot("scans")
    return {
        "runs": len(rows),
        "route_m": round(sum(r["route_m"] for r in rows), 1),
        "nodes": nodes,
        "unlabelled": tot("unlabelled"),
        "node_accuracy": tot("node_correct") / max(nodes, 1),
        "node_accuracy2": tot("node_correct2") / max(nodes, 1),
        "place_accuracy": tot("place_correct") / max(place, 1),
        "place_accuracy2": tot("place_correct2") / max(place, 1),
        "doors_passed": passed,
        "door_recall": tot("doors_detected") / max(passed, 1),
        "door_precision": tot("doorway_nodes_true") / max(dn, 1),
        "doorway_nodes": dn,
        "doorway_duplicates": tot("doorway_nodes_duplicate"),
        "areas": tot("areas"),
        "spaces_visited": tot("spaces_visited"),
        "areas_pure": tot("areas_pure"),
        "spaces_split": tot("spaces_split"),
        "areas_class_right": tot("areas_class_right"),
        "scan_accuracy": sum(r["scan_accuracy"] * r["scans"] for r in rows) / max(scans, 1),
        "scan_accuracy2_no_doorway": sum(r["scan_accuracy2_no_doorway"] * r["scans"] for r in rows)
        / max(scans, 1),
        "collisions": tot("collisions"),
        "known_beams": sum(r["known_beams"] * r["scans"] for r in rows) / max(scans, 1),
        "core_ms_p50": float(np.median(np.concatenate([r["_seconds"] for r in rows])) * 1e3),
        "core_ms_p99": float(np.quantile(np.concatenate([r["_seconds"] for r in rows]), 0.99) * 1e3),
        "confusion": dict(sorted(sum((Counter(r["confusion"]) for r in rows), Counter()).items())),
    }


CONFIGS = [
    Config("360, exact odometry", "360", False),
    Config("360, drift", "360", True),
    Config("front 180 + rear, exact odometry", "front", False),
    Config("front 180 + rear, drift", "front", True),
    Config("front 180 + rear (min resampling), drift", "front", True, front="min"),
    Config("front 180 + rear (hit radius 0.15 m), drift", "front", True, hit_radius=0.15),
    Config(
        "front 180, rear interpolated only (no local map), drift",
        "front",
        True,
        use_local_map=False,
        min_coverage=0.0,  # nothing would vote: without the map a front laser covers half the turn
    ),
    Config("360, drift, edges along the path only (no visibility links)", "360", True, links=False),
    Config("front 180 + rear, drift, edges along the path only", "front", True, links=False),
    Config("front 180 + rear, drift, every label votes (min_coverage 0)", "front", True, min_coverage=0.0),
    Config("front 180 + rear (min_coverage 0.85), drift", "front", True, min_coverage=0.85),
]


def _pct(v: float) -> str:
    return f"{100 * v:.1f} %"


def _row(name: str, s: dict[str, Any]) -> str:
    return (
        f"| {name} | {s['nodes']} ({s['unlabelled']}) | {_pct(s['node_accuracy'])} | {_pct(s['node_accuracy2'])} | "
        f"{_pct(s['door_recall'])} ({s['doors_passed']}) | {_pct(s['door_precision'])} ({s['doorway_nodes']}) | "
        f"{s['areas']} / {s['spaces_visited']} | {s['areas_pure']} | {s['spaces_split']} | "
        f"{_pct(s['scan_accuracy'])} | {s['core_ms_p50']:.2f} / {s['core_ms_p99']:.2f} |"
    )


def markdown(summary: dict[str, dict[str, Any]], command: str, meta: dict[str, Any]) -> str:
    head = [
        "| configuration | nodes (unlabelled) | node acc. | node acc., hallway = corridor | door recall (passed) "
        "| door precision (doorway nodes) | areas / spaces visited | pure areas | spaces split | scan acc. "
        "| core ms p50 / p99 |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    first = next(iter(summary.values()))
    lines = [
        "# Navigation graph, doorways and areas in the simulator",
        "",
        f"Command: `{command}` ({meta['seconds']:.0f} s on this machine).",
        "",
        f"Model: `{meta['model']}` (classes {', '.join(meta['classes'])}; trained on generated buildings "
        f"{meta['trained_on']}). Test buildings: `generate_building(seed)` for seeds {meta['seeds']}, none of them "
        f"seen in training; a route through up to {meta['rooms']} rooms each ({first['route_m']:.0f} m in all, "
        f"SimBase at 0.6 m/s); a scan every {SCAN_PERIOD} s ray cast from the true pose with {NOISE_STD} m noise; "
        "graph d = 1 m, N = 10. *exact*: odometry = true pose; *drift*: SimBase's default odometry noise.",
        "",
        *head,
    ]
    rest: list[str] = []
    for name, s in summary.items():
        (lines if len(lines) < 15 and "(" not in name and "only" not in name else rest).append(_row(name, s))
    lines += ["", "Variants (what each design choice is worth):", "", *head, *rest, ""]
    lines += [
        "Columns:",
        "",
        "- *unlabelled*: place nodes without a label at the end: every scan in the window when the robot was "
        f"there had less than the graph's min_coverage ({GraphParams.min_coverage:.2f}) of its 360° beams "
        "measured or hit in the local map (a front laser right after the start of a route), and the robot "
        "never came back. They count as wrong in the accuracies.",
        "- *node acc.*: a place node is right when its majority label is the class of the space (room, "
        "corridor, hall = hallway) its true position lies in; a doorway node is right when its true position "
        f"is within {DOOR_MATCH} m of a true door's centre. Over all nodes.",
        "- *hallway = corridor*: the same with hallway and corridor counted as one class, the book's two "
        "place-node classes (room, corridor; Sect. 7.2.2).",
        "- *door recall*: doors the robot passed through (its true position entered the opening) that got a "
        "doorway node; *precision*: doorway nodes at a true door.",
        "- *areas / spaces visited*: areas of the topological map against rooms, halls and corridors the "
        "robot entered; *pure*: areas whose nodes all lie in one space; *spaces split*: spaces whose nodes "
        "fell into several areas (a corridor entered twice from different doors without driving between "
        "the two stretches stays two areas until the robot does).",
        "- *scan acc.*: the classifier's label of each scan against the label of the cell the robot is in "
        "(4 classes, doorway cells included): the classifier's own accuracy along the route.",
        "- *core ms*: per scan, local map + full scan + doorway detector + graph + areas (classification "
        f"excluded), on this shared 2-core machine under the other users' load (load average "
        f"{', '.join(str(v) for v in meta['load_average'])} at the end of the run): the p99 mostly measures "
        "that load.",
        "",
        "Place-node confusion (true -> node label), all runs of each configuration:",
        "",
    ]
    for name, s in summary.items():
        conf = ", ".join(f"{k} {v}" for k, v in s["confusion"].items())
        lines.append(f"- {name}: {conf}")
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.evaluate_navigation",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--out", type=Path, default=Path("docs/results"))
    ap.add_argument("--model", type=Path, default=None, help="place model (default: the bundled one)")
    ap.add_argument("--seeds", default="0,1,2,3", help="building seeds, comma-separated (default 0,1,2,3)")
    ap.add_argument("--rooms", type=int, default=8, help="rooms per route (default 8)")
    ap.add_argument("--configs", default=None, help="indices of configurations to run (default all)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    model_path = args.model or default_model_path()
    model = PlaceModel.load(model_path)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    trained_on = ", ".join(model.data.maps[:2]) + (
        f", … ({len(model.data.maps)} maps)" if len(model.data.maps) > 2 else ""
    )
    configs = CONFIGS if args.configs is None else [CONFIGS[int(i)] for i in args.configs.split(",")]
    per_config: dict[str, list[dict[str, Any]]] = {c.name: [] for c in configs}
    t0 = time.perf_counter()
    for seed in seeds:
        building = generate_building(seed)
        route = plan_route(building, args.rooms, np.random.default_rng(seed))
        runs = {d: drive(building, route, drift=d, seed=seed) for d in (False, True)}
        for cfg in configs:
            run = runs[cfg.drift]
            res = run_pipeline(building, run, model, cfg, seed)
            row = score(building, run, res, model)
            per_config[cfg.name].append(row)
            print(
                f"seed {seed} {cfg.name}: nodes {row['nodes']} ok {row['node_correct']}, doors "
                f"{row['doors_detected']}/{row['doors_passed']} (nodes {row['doorway_nodes']}), "
                f"areas {row['areas']}/{row['spaces_visited']}, scans {row['scan_accuracy']:.3f}",
                file=sys.stderr,
            )
    summary = {name: summarize(rows) for name, rows in per_config.items()}
    command = "python -m tools.evaluate_navigation " + " ".join(argv if argv is not None else sys.argv[1:])
    meta = {
        "model": str(model_path.relative_to(Path.cwd()))
        if model_path.is_relative_to(Path.cwd())
        else str(model_path),
        "classes": list(model.classes),
        "trained_on": trained_on,
        "seeds": seeds,
        "rooms": args.rooms,
        "seconds": round(time.perf_counter() - t0, 1),
        "load_average": [round(v, 2) for v in os.getloadavg()],
    }
    for rows in per_config.values():
        for r in rows:
            r.pop("_seconds")
    doc = {"command": command.strip(), "meta": meta, "summary": summary, "runs": per_config}
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out / "navigation.json", json.dumps(doc, indent=2, allow_nan=False) + "\n")
    atomic_write_text(args.out / "navigation.md", markdown(summary, command.strip(), meta))
    print(markdown(summary, command.strip(), meta))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
