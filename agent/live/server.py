"""The Foxglove WebSocket server of the live view (``foxglove-sdk``), fed by the agent's loop.

:class:`LiveView` owns a ``foxglove.Context`` of its own (nothing else the process logs
reaches it), starts the SDK's server on ``[HOST:]PORT`` and advertises one channel per
layer (:data:`TOPICS`). The agent calls it, in its event loop, like a subscriber:
:meth:`LiveView.on_step` after each processed scan, :meth:`LiveView.on_state` when the
graph or the areas changed, :meth:`LiveView.on_say` for each line of the conversation,
:meth:`LiveView.on_concepts` with the conceptual map, :meth:`LiveView.tick` now and then.

Cost: the server's listener counts the subscriptions (it runs on the SDK's threads); while
no client subscribes to anything, each call returns after one integer test, so a robot
with the live view on but nobody watching pays nothing measurable
(``tools/bench_live.py``). With clients, only the channels someone subscribed to are
encoded (``has_sinks``). The SDK queues what a slow client cannot take and drops its oldest
data messages (``message_backlog_size``), so a slow viewer never holds up the agent.

State layers (graph, areas, people, the labelled map, the occupancy grid) are sent again
to a client that subscribes late: the listener marks the channel and the next call from
the loop sends its latest message.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import foxglove
import numpy as np
from foxglove import messages as fg
from foxglove.channels import (
    FrameTransformsChannel,
    GridChannel,
    LaserScanChannel,
    LogChannel,
    SceneUpdateChannel,
)
from foxglove.websocket import ServerListener, WebSocketServer

from agent.bus.scene import graph_scene, people_scene
from agent.bus.schemas import SCHEMAS
from agent.live import layers
from knowledge.metric.mapping import MappingParams, ScanMapper

log = logging.getLogger(__name__)

#: Every topic the live view advertises: topic → what it carries.
TOPICS: dict[str, str] = {
    "/scan": "foxglove.LaserScan: the scan as measured (frame laser)",
    "/scan/full": "foxglove.LaserScan: the 360° scan the classifier saw (frame laser)",
    "/map": "foxglove.Grid: the occupancy grid of the scans at their odometry poses (frame odom)",
    "/labels": "foxglove.Grid: the labelled map loaded with [foxglove] labels (frame map)",
    "/graph": "foxglove.SceneUpdate: the navigation graph, nodes coloured by class (frame odom)",
    "/areas": "foxglove.SceneUpdate: each area's class, id and names (frame odom)",
    "/people": "foxglove.SceneUpdate: tracked people and legs (frame odom)",
    "/place": "loci.place/1 (JSON): the current class, its histogram, node, coverage",
    "/tf": "foxglove.FrameTransforms: map → odom → base_link → laser",
    "/conversation": "foxglove.Log: what the robot says and asks",
}


@dataclass(frozen=True)
class LabelledMap:
    """A label image placed in the world: ``(rows, cols)`` class codes, metres per cell, origin."""

    labels: np.ndarray
    resolution: float
    origin: tuple[float, float, float]

    @classmethod
    def load(cls, yaml_path: str | Path) -> LabelledMap:
        """Read a label image through its map_server YAML (``loci places label`` writes both).

        Raises:
            MapError: the YAML or the image cannot be read.
        """
        import yaml

        from knowledge.errors import MapError
        from knowledge.labels import read_label_image

        p = Path(yaml_path)
        try:
            meta = yaml.safe_load(p.read_text())
            image = p.parent / str(meta["image"])
            resolution = float(meta["resolution"])
            origin = tuple(float(v) for v in meta.get("origin", (0.0, 0.0, 0.0)))[:3]
        except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as exc:
            raise MapError(f"{p}: not a label map's YAML (image, resolution, origin): {exc}") from exc
        return cls(read_label_image(image), resolution, (origin[0], origin[1], origin[2]))


def _json_schema(schema_id: str) -> foxglove.Schema:
    doc = SCHEMAS.get(schema_id).json_schema()
    return foxglove.Schema(name=schema_id, encoding="jsonschema", data=json.dumps(doc).encode())


class _Listener(ServerListener):
    """Counts subscriptions and remembers which channels a client newly subscribed to (SDK threads)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscriptions = 0
        self.clients: set[int] = set()
        self.fresh: set[str] = set()

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.subscriptions += 1
            self.clients.add(int(client.id))
            self.fresh.add(str(channel.topic))

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.subscriptions = max(0, self.subscriptions - 1)

    def take_fresh(self) -> set[str]:
        with self.lock:
            fresh, self.fresh = self.fresh, set()
        return fresh


class LiveView:
    """The live view's server (see the module docstring).

    Args:
        host, port: where to listen (port 0: a free one, read back from :attr:`port`).
        mount: the laser's pose on the robot ``(x, y, yaw)`` (for ``base_link → laser``).
        labels: a labelled map to show as ``/labels``.
        grid_period: seconds between two ``/map`` messages.
        resolution: metres per cell of ``/map``.
        name: the server's name in the app.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8765,
        *,
        mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
        labels: LabelledMap | None = None,
        grid_period: float = 1.0,
        resolution: float = 0.1,
        name: str = "genius-loci",
    ) -> None:
        self.mount = tuple(float(v) for v in mount)
        self.labels = labels
        self.grid_period = grid_period
        self.resolution = resolution
        self.context = foxglove.Context()
        self._listener = _Listener()
        ctx = self.context
        self.channels: dict[str, Any] = {
            "/scan": LaserScanChannel("/scan", context=ctx),
            "/scan/full": LaserScanChannel("/scan/full", context=ctx),
            "/map": GridChannel("/map", context=ctx),
            "/graph": SceneUpdateChannel("/graph", context=ctx),
            "/areas": SceneUpdateChannel("/areas", context=ctx),
            "/people": SceneUpdateChannel("/people", context=ctx),
            "/place": foxglove.Channel(
                "/place", schema=_json_schema("loci.place/1"), message_encoding="json", context=ctx
            ),
            "/tf": FrameTransformsChannel("/tf", context=ctx),
            "/conversation": LogChannel("/conversation", context=ctx),
        }
        if labels is not None:
            self.channels["/labels"] = GridChannel("/labels", context=ctx)
        self._server: WebSocketServer | None = foxglove.start_server(
            name=name, host=host, port=port, context=ctx, server_listener=self._listener
        )
        self.port = int(self._server.port)
        self.host = host
        self._latest: dict[str, tuple[Any, int]] = {}
        self._mapper: ScanMapper | None = None
        self._last_grid = -math.inf
        self._grid_lock = threading.Lock()
        self._grid_busy = threading.Event()
        self._graph: Mapping[str, Any] | None = None
        self._areas: Mapping[str, Any] | None = None
        self._names: dict[int, list[str]] = {}
        self._concepts_version: Any = None
        self._last_concepts = -math.inf
        self.sent: dict[str, int] = dict.fromkeys(self.channels, 0)
        if labels is not None:
            self._latest["/labels"] = (layers.label_grid(labels.labels, labels.resolution, labels.origin), 0)
        log.info("Foxglove live view on ws://%s:%d", host, self.port)

    # ------------------------------------------------------------------ helpers
    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    @property
    def watched(self) -> bool:
        """Whether any client subscribes to any channel now."""
        return self._listener.subscriptions > 0

    def _log(self, topic: str, message: Any, log_time: int) -> None:
        self.channels[topic].log(message, log_time=log_time)
        self.sent[topic] += 1

    def _wants(self, topic: str) -> bool:
        return bool(self.channels[topic].has_sinks())

    def _keep(self, topic: str, message: Any, log_time: int) -> None:
        """Remember a state layer's latest message and send it to whoever subscribes."""
        self._latest[topic] = (message, log_time)
        if self._wants(topic):
            self._log(topic, message, log_time)

    def _resend(self) -> None:
        fresh = self._listener.take_fresh()
        for topic in fresh:
            kept = self._state_message(topic)
            if kept is not None and topic in self.channels:
                self._log(topic, kept[0], kept[1])

    # ------------------------------------------------------------------ called by the agent
    def on_step(self, result: Any) -> None:
        """One processed scan (a :class:`~agent.core.pipeline.StepResult`)."""
        if self._listener.subscriptions <= 0:
            return
        self._resend()
        stamp = float(result.stamp)
        ns = int(stamp * 1e9)
        pose = result.pose
        laser = (float(pose.x), float(pose.y), float(pose.theta))
        scan = result.scan
        if self._wants("/tf"):
            self._log("/tf", layers.transforms(laser, self.mount, stamp, laser_frame=scan.frame_id), ns)  # type: ignore[arg-type]
        if self._wants("/scan"):
            self._log(
                "/scan",
                _laser_scan(stamp, scan.frame_id, scan.angle_min, scan.angle_increment, scan.ranges),
                ns,
            )
        if self._wants("/scan/full"):
            n = int(result.ranges.shape[0])
            self._log(
                "/scan/full", _laser_scan(stamp, scan.frame_id, 0.0, 2.0 * math.pi / n, result.ranges), ns
            )
        if self._wants("/place"):
            from agent.core.pipeline import place_message

            self._log("/place", json.dumps(place_message(result)).encode(), ns)
        if result.people is not None and self._wants("/people"):
            self._keep("/people", people_scene(result.people.to_json("odom")), ns)
        self._update_grid(result, stamp, ns)

    def _update_grid(self, result: Any, stamp: float, ns: int) -> None:
        if not self._wants("/map"):
            return
        if self._mapper is None:
            self._mapper = ScanMapper(MappingParams(resolution=self.resolution))
        scan, pose = result.scan, result.pose
        self._mapper.add(
            scan.ranges,
            scan.angles,
            (pose.x, pose.y, pose.theta),
            range_max=scan.range_max,
            range_min=scan.range_min,
        )
        now = time.monotonic()
        if now - self._last_grid >= self.grid_period:
            self._last_grid = now
            self._keep("/map", layers.occupancy_grid(self._mapper.grid("scans"), stamp), ns)

    def on_state(self, graph: Mapping[str, Any], areas: Mapping[str, Any]) -> None:
        """The graph and the areas changed (``loci.graph/1``, ``loci.areas/1`` messages).

        Only kept while nobody watches; the scenes are built when someone subscribes."""
        self._graph, self._areas = graph, areas
        self._latest.pop("/graph", None)
        self._latest.pop("/areas", None)
        if self._listener.subscriptions <= 0:
            return
        for topic in ("/graph", "/areas"):
            if self._wants(topic):
                self._log(topic, *self._state_message(topic))  # type: ignore[misc]

    def _state_message(self, topic: str) -> tuple[Any, int] | None:
        """The latest message of a state layer (built from the kept graph and areas if need be)."""
        kept = self._latest.get(topic)
        if (
            kept is not None
            or topic not in ("/graph", "/areas")
            or self._graph is None
            or self._areas is None
        ):
            return kept
        graph, areas = self._graph, self._areas
        ns = int(float(graph.get("stamp", 0.0)) * 1e9)
        if topic == "/graph":
            self._latest[topic] = (graph_scene(graph), ns)
        else:
            self._latest[topic] = (layers.named_areas_scene(areas, graph, self._names), ns)
        return self._latest[topic]

    def concepts_due(self, period: float = 1.0) -> bool:
        """Whether to look at the conceptual map again (at most once per ``period`` seconds)."""
        now = time.monotonic()
        if now - self._last_concepts < period:
            return False
        self._last_concepts = now
        return True

    def on_concepts(self, snapshot: Mapping[str, Any] | None) -> None:
        """The conceptual map's snapshot; its names and types label the areas."""
        if snapshot is None:
            return
        version = (snapshot.get("version"), snapshot.get("reasoned"))
        if version == self._concepts_version:
            return
        self._concepts_version = version
        names = layers.area_names(snapshot)
        if names != self._names:
            self._names = names
            if self._graph is not None and self._areas is not None:
                self.on_state(self._graph, self._areas)

    def on_say(self, stream: str, message: Mapping[str, Any]) -> None:
        """A message the agent sends on ``dialogue/say`` or ``dialogue/ask``: a line of the conversation."""
        text = message.get("text")
        if not text or not self._wants("/conversation"):
            return
        stamp = float(message.get("stamp") or time.time())
        level = fg.LogLevel.Warning if stream.endswith("ask") else fg.LogLevel.Info
        self._log(
            "/conversation",
            fg.Log(
                timestamp=layers.timestamp(stamp),
                level=level,
                message=str(text),
                name="robot",
                file=stream,
                line=0,
            ),
            int(stamp * 1e9),
        )

    def tick(self) -> None:
        """Send the state layers to clients that subscribed since the last call."""
        if self._listener.subscriptions > 0:
            self._resend()

    def close(self) -> None:
        """Stop the server (idempotent)."""
        server, self._server = self._server, None
        if server is not None:
            server.stop()
            for ch in self.channels.values():
                ch.close()


def _laser_scan(
    stamp: float, frame_id: str, angle_min: float, increment: float, ranges: np.ndarray
) -> fg.LaserScan:
    n = int(ranges.shape[0])
    return fg.LaserScan(
        timestamp=layers.timestamp(stamp),
        frame_id=frame_id,
        pose=fg.Pose(
            position=fg.Vector3(x=0.0, y=0.0, z=0.0), orientation=fg.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        ),
        start_angle=float(angle_min),
        end_angle=float(angle_min + increment * (n - 1)),
        ranges=np.asarray(ranges, dtype=np.float64).tolist(),
        intensities=[],
    )


def start_live_view(config: Any, *, mount: tuple[float, float, float], name: str) -> LiveView:
    """A :class:`LiveView` from ``[foxglove]`` (:class:`~agent.live.config.FoxgloveConfig`)."""
    host, port = config.address
    labels = LabelledMap.load(config.labels) if config.labels else None
    return LiveView(
        host,
        port,
        mount=mount,
        labels=labels,
        grid_period=config.grid_period,
        resolution=config.resolution,
        name=name,
    )
