"""The navigation map of Sect. 7.2.2: nodes dropped along the robot's path.

Rules (positions in the odometry frame, metres):

* **Place nodes**: a node is added at the robot's position when the robot is farther than
  ``node_distance`` (d, default 1 m) from every node. The robot *reaches* a place node when
  it comes within ``reach`` of it (default d/2; the reach discs of nodes at least d apart do
  not overlap) and leaves it beyond 1.25 × ``reach``.
* **Edges follow the path**: from the node the robot was last at (created or reached) to
  the node it creates or reaches next; the edge length is the distance between the nodes.
  Given the full scan (``ranges``), a place node created or reached is also joined to the
  place nodes within ``link_radius`` the robot can see along measured beams (a front
  laser's interpolated rear beams see through walls), unless the line crosses a doorway.
* **Labels by majority vote**: the graph keeps the last ``window`` (N) place labels of the
  classifier. When a place node is created or reached, the labels in that window are added
  to the node's vote counts, and its label is the class with most votes. A revisit with
  different evidence can therefore flip it; a tie keeps the current label. Labels in
  ``ignore_labels`` ("doorway" by default: doorways are their own nodes) do not enter the
  window. Labels of scans whose 360° view is mostly guessed abstain: with a front laser the
  rear half is simulated from the local map (Sect. 3.5), and right after start-up (or
  after a long stop) that map is empty and the rear beams are interpolated. Given the
  scan's ``coverage`` (the share of its beams measured or hit in the local map), a label
  votes only when ``coverage >= min_coverage`` (0.75 by default; a front laser alone gives
  0.5); an abstaining scan keeps its slot in the window, so the window stays the last N
  scans. A node reached while no label in the window may vote gets no votes then (a node
  created so has no label until a later visit brings some).
* **Doorway nodes** are added where the doorway detector
  (:class:`~knowledge.navigation.doorways.DoorwayDetector`) reports a passage, at the
  opening's centre, with its width and orientation. A doorway reported within
  ``door_merge`` of an existing doorway node is that node again (a revisit). A doorway node
  is reached only that way, never by coming close to it from beside it. While the robot is
  inside an opening (``in_opening``), no place node is dropped and none is reached, so that
  the doorway node, not a place node in the door, links the two sides.

The graph also answers the queries navigation needs: the nearest node, and the shortest
path between two nodes over edge lengths (A* with the straight-line heuristic).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections import Counter, deque
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np

from knowledge.navigation.doorways import Doorway

__all__ = ["DOORWAY", "PLACE", "GraphParams", "GraphUpdate", "NavigationGraph", "Node"]

PLACE = "place"
DOORWAY = "doorway"
NODE_KINDS = (PLACE, DOORWAY)


@dataclass(frozen=True)
class GraphParams:
    """How the navigation graph grows.

    Attributes:
        node_distance: metres; a node is added when the robot is farther than this from every node.
        reach: metres; the robot is at a node within this distance (None: ``node_distance / 2``).
        window: N, the number of recent place labels voted on when a node is reached.
        ignore_labels: classifier labels that do not vote for place nodes.
        door_merge: metres; a doorway reported this close to a doorway node is that node.
        link_radius: metres (None: ``1.5 × node_distance``); with a scan, a node the robot
            creates or reaches is also joined to the place nodes this close that it can see.
        min_coverage: share of a scan's 360° beams that must be known (measured, or hit in
            the local map) for its label to vote (0: every label votes).
    """

    node_distance: float = 1.0
    reach: float | None = None
    window: int = 10
    ignore_labels: tuple[str, ...] = ("doorway",)
    door_merge: float = 0.7
    link_radius: float | None = None
    min_coverage: float = 0.75

    def __post_init__(self) -> None:
        if not (math.isfinite(self.node_distance) and self.node_distance > 0):
            raise ValueError(f"node_distance must be a positive number of metres, got {self.node_distance!r}")
        if self.reach is not None and not (0 < self.reach <= self.node_distance):
            raise ValueError(f"reach must be in (0, node_distance] metres or None, got {self.reach!r}")
        if isinstance(self.window, bool) or int(self.window) != self.window or self.window < 1:
            raise ValueError(f"window must be a positive integer (N labels), got {self.window!r}")
        if not (math.isfinite(self.door_merge) and self.door_merge > 0):
            raise ValueError(f"door_merge must be a positive number of metres, got {self.door_merge!r}")
        if self.link_radius is not None and not (math.isfinite(self.link_radius) and self.link_radius >= 0):
            raise ValueError(f"link_radius must be >= 0 metres or None, got {self.link_radius!r}")
        if isinstance(self.min_coverage, bool) or not (
            isinstance(self.min_coverage, int | float) and 0.0 <= self.min_coverage <= 1.0
        ):
            raise ValueError(
                f"min_coverage must be a share of the beams in [0, 1] (0: every label votes), got {self.min_coverage!r}"
            )
        object.__setattr__(self, "ignore_labels", tuple(str(v) for v in self.ignore_labels))

    @property
    def reach_radius(self) -> float:
        return self.node_distance / 2.0 if self.reach is None else float(self.reach)

    @property
    def link_radius_m(self) -> float:
        return 1.5 * self.node_distance if self.link_radius is None else float(self.link_radius)


@dataclass
class Node:
    """A navigation node.

    Attributes:
        id: its id (unique in the graph, never reused).
        kind: "place" or "doorway".
        x, y: odometry-frame position, metres.
        votes: place label → number of votes (place nodes).
        label: the majority label (None before any vote); "doorway" for doorway nodes.
        visits: how many times the robot created or reached it (doorways: passed through).
        width: doorway width, metres (doorway nodes).
        orientation: doorway normal, radians, the way it was first passed (doorway nodes).
    """

    id: int
    kind: str
    x: float
    y: float
    votes: dict[str, int] = field(default_factory=dict)
    label: str | None = None
    visits: int = 0
    width: float | None = None
    orientation: float | None = None

    @property
    def xy(self) -> tuple[float, float]:
        return (self.x, self.y)

    def add_votes(self, counts: Mapping[str, int]) -> bool:
        """Add vote counts; returns whether the label changed (ties keep the current label)."""
        for k, v in counts.items():
            if v:
                self.votes[k] = self.votes.get(k, 0) + int(v)
        if not self.votes:
            return False
        top = max(self.votes.values())
        if self.label is not None and self.votes.get(self.label, 0) == top:
            return False
        new = min(k for k, v in self.votes.items() if v == top)
        changed = new != self.label
        self.label = new
        return changed


@dataclass(frozen=True)
class GraphUpdate:
    """What one :meth:`NavigationGraph.update` changed.

    Attributes:
        added: ids of nodes created.
        reached: ids of existing nodes reached (or doorways passed again).
        relabelled: ids of place nodes whose majority label changed (new nodes included
            when they got a label).
        edges: ``(a, b)`` edges created, ``a < b``.
        current: the node the robot was last at.
    """

    added: tuple[int, ...] = ()
    reached: tuple[int, ...] = ()
    relabelled: tuple[int, ...] = ()
    edges: tuple[tuple[int, int], ...] = ()
    current: int | None = None

    @property
    def changed(self) -> bool:
        """Whether nodes, edges or labels changed (the areas need recomputing)."""
        return bool(self.added or self.relabelled or self.edges)


class NavigationGraph:
    """The navigation graph (see the module docstring).

    Per scan: ``graph.update(pose, label, doorway, in_opening=detector.passing)``.
    """

    def __init__(self, params: GraphParams | None = None) -> None:
        self.params = params or GraphParams()
        self.nodes: dict[int, Node] = {}
        self._adj: dict[int, dict[int, float]] = {}
        # the last N place labels; None for a scan whose label abstained (low coverage)
        self.recent: deque[str | None] = deque(maxlen=self.params.window)
        self.current: int | None = None
        self._at: int | None = None
        self._next_id = 1
        self.revision = 0
        self._cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return len(self.nodes)

    def __contains__(self, node_id: object) -> bool:
        return node_id in self.nodes

    @property
    def next_id(self) -> int:
        return self._next_id

    def node(self, node_id: int) -> Node:
        try:
            return self.nodes[node_id]
        except KeyError:
            raise KeyError(f"no navigation node {node_id}") from None

    def edges(self) -> Iterator[tuple[int, int, float]]:
        """Every edge once: ``(a, b, length)`` with ``a < b``, sorted."""
        for a in sorted(self._adj):
            for b in sorted(self._adj[a]):
                if a < b:
                    yield a, b, self._adj[a][b]

    def neighbours(self, node_id: int) -> dict[int, float]:
        """Neighbour id → edge length (metres)."""
        self.node(node_id)
        return dict(self._adj[node_id])

    def has_edge(self, a: int, b: int) -> bool:
        return b in self._adj.get(a, {})

    def place_nodes(self) -> list[Node]:
        return [n for n in self.nodes.values() if n.kind == PLACE]

    def doorway_nodes(self) -> list[Node]:
        return [n for n in self.nodes.values() if n.kind == DOORWAY]

    def positions(self, ids: Iterable[int] | None = None) -> np.ndarray:
        """``(k, 2)`` float64 odometry-frame positions of ``ids`` (all nodes by id order if None)."""
        keys = sorted(self.nodes) if ids is None else list(ids)
        if not keys:
            return np.empty((0, 2))
        return np.array([self.nodes[k].xy for k in keys], dtype=np.float64)

    def _index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node ids ``(N,)``, positions ``(N, 2)`` and is-place ``(N,)``, rebuilt when nodes come or go."""
        if self._cache is None:
            ids = np.fromiter(self.nodes, dtype=np.int64, count=len(self.nodes))
            xy = self.positions(ids.tolist()) if ids.size else np.empty((0, 2))
            place = np.array([self.nodes[int(k)].kind == PLACE for k in ids], dtype=bool)
            self._cache = (ids, xy, place)
        return self._cache

    def nearest(
        self, xy: tuple[float, float] | np.ndarray, kind: str | None = None
    ) -> tuple[int, float] | None:
        """The node nearest to ``xy`` (of ``kind`` if given) and its distance, or None."""
        ids, pos, place = self._index()
        if kind is not None:
            sel = place if kind == PLACE else ~place
            ids, pos = ids[sel], pos[sel]
        if ids.size == 0:
            return None
        p = np.asarray(xy, dtype=np.float64)
        d = np.hypot(pos[:, 0] - p[0], pos[:, 1] - p[1])
        i = int(np.argmin(d))
        return int(ids[i]), float(d[i])

    def path(self, start: int, goal: int) -> list[int] | None:
        """The shortest path ``[start, ..., goal]`` over edge lengths (A*), or None if unreachable."""
        self.node(start)
        gx, gy = self.node(goal).xy
        h = {k: math.hypot(n.x - gx, n.y - gy) for k, n in self.nodes.items()}
        dist = {start: 0.0}
        prev: dict[int, int] = {}
        heap = [(h[start], start)]
        done: set[int] = set()
        while heap:
            _, u = heapq.heappop(heap)
            if u in done:
                continue
            if u == goal:
                out = [u]
                while out[-1] != start:
                    out.append(prev[out[-1]])
                return out[::-1]
            done.add(u)
            for v, w in self._adj[u].items():
                nd = dist[u] + w
                if nd < dist.get(v, math.inf):
                    dist[v], prev[v] = nd, u
                    heapq.heappush(heap, (nd + h[v], v))
        return None

    def path_length(self, path: list[int]) -> float:
        """Metres along a path of adjacent nodes."""
        return sum(self._adj[a][b] for a, b in itertools.pairwise(path))

    def window_counts(self) -> Counter[str]:
        """Label counts of the current window of recent place labels."""
        return Counter(label for label in self.recent if label is not None)

    # ------------------------------------------------------------------ building
    def add_node(
        self,
        kind: str,
        xy: tuple[float, float],
        *,
        votes: Mapping[str, int] | None = None,
        width: float | None = None,
        orientation: float | None = None,
        node_id: int | None = None,
    ) -> Node:
        """Insert a node directly (loading, tests, corrections); :meth:`update` is the usual way."""
        if kind not in NODE_KINDS:
            raise ValueError(f"node kind must be one of {NODE_KINDS}, got {kind!r}")
        x, y = float(xy[0]), float(xy[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"node position must be finite metres, got {xy!r}")
        nid = self._next_id if node_id is None else int(node_id)
        if nid in self.nodes:
            raise ValueError(f"navigation node {nid} exists already")
        node = Node(nid, kind, x, y, width=width, orientation=orientation)
        if kind == DOORWAY:
            node.label = DOORWAY
        elif votes:
            node.add_votes(votes)
        self.nodes[nid] = node
        self._adj[nid] = {}
        if self._cache is not None:
            ids, pos, place = self._cache
            self._cache = (
                np.append(ids, nid),
                np.concatenate((pos, [[x, y]])),
                np.append(place, kind == PLACE),
            )
        self._next_id = max(self._next_id, nid + 1)
        self.revision += 1
        return node

    def add_edge(self, a: int, b: int) -> bool:
        """Join two nodes (length = their distance); returns whether the edge is new."""
        na, nb = self.node(a), self.node(b)
        if a == b or b in self._adj[a]:
            return False
        length = math.hypot(na.x - nb.x, na.y - nb.y)
        self._adj[a][b] = self._adj[b][a] = length
        self.revision += 1
        return True

    def remove_edge(self, a: int, b: int) -> bool:
        """Cut the edge between two nodes; returns whether there was one."""
        self.node(a)
        self.node(b)
        if b not in self._adj[a]:
            return False
        del self._adj[a][b], self._adj[b][a]
        self.revision += 1
        return True

    def add_votes(self, node_id: int, counts: Mapping[str, int]) -> bool:
        """Add label votes to a place node (e.g. a label the user asserted); returns whether its label changed."""
        node = self.node(node_id)
        if node.kind != PLACE:
            raise ValueError(f"node {node_id} is a {node.kind} node; only place nodes take label votes")
        changed = node.add_votes(counts)
        self.revision += 1
        return changed

    def remove_node(self, node_id: int, *, reconnect: bool = True) -> None:
        """Delete a node (e.g. a false doorway); with ``reconnect`` its neighbours are joined pairwise."""
        self.node(node_id)
        nbrs = sorted(self._adj.pop(node_id))
        for v in nbrs:
            del self._adj[v][node_id]
        del self.nodes[node_id]
        self._cache = None
        if reconnect:
            for i, a in enumerate(nbrs):
                for b in nbrs[i + 1 :]:
                    self.add_edge(a, b)
        if self.current == node_id:
            self.current = None
        if self._at == node_id:
            self._at = None
        self.revision += 1

    def _link_visible(
        self, nid: int, pose: np.ndarray, scan: np.ndarray, known: np.ndarray | None
    ) -> list[tuple[int, int]]:
        """Join ``nid`` to the nearby place nodes the robot sees at ``pose`` (see :meth:`update`)."""
        node = self.nodes[nid]
        radius = self.params.link_radius_m
        n = scan.size
        step = 2.0 * math.pi / n
        out: list[tuple[int, int]] = []
        ids, pos, place = self._index()
        near = place & (np.hypot(pos[:, 0] - node.x, pos[:, 1] - node.y) <= radius)
        for k in ids[near].tolist():
            other = self.nodes[k]
            if k == nid or k in self._adj[nid]:
                continue
            dx, dy = other.x - pose[0], other.y - pose[1]
            dist = math.hypot(dx, dy)
            i = round((math.atan2(dy, dx) - pose[2]) / step)
            toward = [(i - 1) % n, i % n, (i + 1) % n]
            # the robot must see past the node (by about its own size) along the beams towards
            # it, and those beams must be measured, not interpolated across a gap in the local map
            if scan[toward].min() < dist + 0.2 or (known is not None and not known[toward].all()):
                continue
            if self._crosses_doorway(node.xy, other.xy):
                continue
            if self.add_edge(nid, other.id):
                out.append((min(nid, other.id), max(nid, other.id)))
        return out

    def _crosses_doorway(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """Whether the segment a–b crosses the opening (widened by 0.3 m a side) of a doorway node."""
        for d in self.nodes.values():
            if d.kind != DOORWAY:
                continue
            o = d.orientation or 0.0
            half = 0.5 * (d.width or 1.0) + 0.3
            tx, ty = -math.sin(o) * half, math.cos(o) * half
            if _segments_cross(a, b, (d.x - tx, d.y - ty), (d.x + tx, d.y + ty)):
                return True
        return False

    def update(
        self,
        pose: np.ndarray | tuple[float, float, float],
        label: str | None = None,
        doorway: Doorway | None = None,
        *,
        in_opening: bool = False,
        ranges: np.ndarray | None = None,
        coverage: float | None = None,
        known: np.ndarray | None = None,
    ) -> GraphUpdate:
        """Advance the graph by one scan.

        Args:
            pose: the robot's odometry-frame ``(x, y, theta)``.
            label: the classifier's label of this scan (None: no classification).
            doorway: a doorway the detector reported on this scan.
            in_opening: the robot is inside an opening now (no place node is dropped or reached).
            ranges: the full 360° scan of this pose (``(n,)`` metres, beam ``i`` at ``i·2π/n``
                from the heading), if available: a place node created or reached is then also
                joined to the place nodes within ``link_radius`` that the robot sees (the beams
                towards them reach beyond them), unless the line to them crosses a doorway
                node's opening. This joins a path that comes back beside its old track, e.g.
                out of a door into a corridor a metre from the corridor's last node, which
                would otherwise split the corridor into two areas.
            coverage: the share of the scan's 360° beams that are known (measured, or hit in
                the local map; :func:`knowledge.metric.rear_beams.assemble_scan`); below
                ``min_coverage`` the label does not vote (None: it votes).
            known: ``(n,)`` bool, the beams of ``ranges`` that are measured or hit in the local
                map (the others are interpolated); only known beams join nodes (None: all).
        """
        p = np.asarray(pose, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"pose must be a finite (x, y, theta), got {pose!r}")
        scan = None
        if ranges is not None:
            scan = np.asarray(ranges, dtype=np.float64)
            if scan.ndim != 1 or scan.size < 3:
                raise ValueError(f"ranges must be a 1-D 360° scan, got shape {scan.shape}")
            if known is not None:
                known = np.asarray(known, dtype=bool)
                if known.shape != scan.shape:
                    raise ValueError(f"known must match ranges {scan.shape}, got shape {known.shape}")
        prm = self.params
        if coverage is not None and not (math.isfinite(coverage) and 0.0 <= coverage <= 1.0):
            raise ValueError(f"coverage must be a share of the beams in [0, 1], got {coverage!r}")
        votes = coverage is None or coverage >= prm.min_coverage
        if label is not None and label not in prm.ignore_labels:
            # an abstaining scan still takes its place in the window: the votes of the scans
            # before it must not be counted again for a node reached later, elsewhere
            self.recent.append(str(label) if votes else None)
        added: list[int] = []
        reached: list[int] = []
        relabelled: list[int] = []
        edges: list[tuple[int, int]] = []

        def arrive(nid: int) -> None:
            if self.current is not None and self.add_edge(self.current, nid):
                edges.append((min(self.current, nid), max(self.current, nid)))
            self.current = nid
            node = self.nodes[nid]
            node.visits += 1
            if node.kind == PLACE and node.add_votes(self.window_counts()):
                relabelled.append(nid)
            if node.kind == PLACE and scan is not None:
                edges.extend(self._link_visible(nid, p, scan, known))

        if doorway is not None:
            near = self.nearest(doorway.center, kind=DOORWAY)
            if near is not None and near[1] <= prm.door_merge:
                door = self.nodes[near[0]]
                door.width = (door.width or doorway.width) * 0.5 + doorway.width * 0.5
                reached.append(door.id)
            else:
                door = self.add_node(
                    DOORWAY, doorway.center, width=doorway.width, orientation=doorway.orientation
                )
                added.append(door.id)
            arrive(door.id)
            self._at = door.id

        if not in_opening:
            near = self.nearest(p[:2])
            if near is None or near[1] > prm.node_distance:
                node = self.add_node(PLACE, (float(p[0]), float(p[1])))
                added.append(node.id)
                arrive(node.id)
                self._at = node.id
            else:
                # only place nodes are reached by coming close: a doorway node is reached by
                # passing through it (the detector), never from the corridor beside it
                place = self.nearest(p[:2], kind=PLACE)
                if place is not None and place[1] <= prm.reach_radius:
                    if place[0] != self._at:
                        self._at = place[0]
                        reached.append(place[0])
                        arrive(place[0])
                elif self._at is not None:
                    at = self.nodes.get(self._at)
                    # leave a node's disc only clearly (no revote from jitter at its edge)
                    if at is None or math.hypot(at.x - p[0], at.y - p[1]) > 1.25 * prm.reach_radius:
                        self._at = None
        if relabelled:
            self.revision += 1
        return GraphUpdate(tuple(added), tuple(reached), tuple(relabelled), tuple(edges), self.current)


def _segments_cross(
    a: tuple[float, float], b: tuple[float, float], c: tuple[float, float], d: tuple[float, float]
) -> bool:
    """Whether the closed segments a–b and c–d intersect."""

    def orient(p: tuple[float, float], q: tuple[float, float], r: tuple[float, float]) -> float:
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    d1, d2 = orient(c, d, a), orient(c, d, b)
    d3, d4 = orient(a, b, c), orient(a, b, d)
    return d1 * d2 <= 0.0 and d3 * d4 <= 0.0 and not (d1 == d2 == 0.0)
