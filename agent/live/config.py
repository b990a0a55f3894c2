"""``[foxglove]``: where the live view listens and what it shows besides the agent's own layers."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The Foxglove app's usual port.
DEFAULT_PORT = 8765


def parse_address(text: str) -> tuple[str, int]:
    """``"[HOST:]PORT"`` → ``(host, port)``; the host defaults to 127.0.0.1 (this machine only).

    Raises:
        ValueError: not a port (0-65535; 0 picks a free one) with an optional host.
    """
    host, sep, port_text = text.strip().rpartition(":")
    if not sep:
        host = "127.0.0.1"
    host = host.strip("[]") or "127.0.0.1"
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise ValueError(
            f"expected [HOST:]PORT for the Foxglove server (e.g. 8765 or 0.0.0.0:8765), got {text!r}"
        )
    return host, port


@dataclass(frozen=True)
class FoxgloveConfig:
    """``[foxglove]`` (docs/foxglove.md).

    Attributes:
        listen: ``"[HOST:]PORT"`` of the WebSocket server; ``""``: no live view. The host
            defaults to 127.0.0.1; ``0.0.0.0:8765`` serves every network the robot is on
            (the protocol has no authentication: only on a trusted network).
        labels: a label image's map_server YAML (``loci places label`` writes one beside the
            image) shown as the layer ``/labels`` in frame ``map``; ``""``: none.
        grid_period: seconds between two messages of the occupancy grid ``/map``.
        resolution: metres per cell of ``/map``.
    """

    listen: str = ""
    labels: str = ""
    grid_period: float = 1.0
    resolution: float = 0.1

    def __post_init__(self) -> None:
        if self.listen:
            parse_address(self.listen)
        if not (math.isfinite(self.grid_period) and self.grid_period > 0):
            raise ValueError(f"grid_period must be > 0 seconds, got {self.grid_period}")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"resolution must be > 0 metres, got {self.resolution}")

    @property
    def on(self) -> bool:
        return bool(self.listen)

    @property
    def address(self) -> tuple[str, int]:
        return parse_address(self.listen or str(DEFAULT_PORT))
