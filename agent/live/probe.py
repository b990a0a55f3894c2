"""A small Foxglove WebSocket client: what a viewer receives from the live view, decoded.

It speaks the protocol as the Foxglove app does (subprotocol ``foxglove.sdk.v1``): reads the
server's ``advertise``, subscribes to topics, and decodes each binary ``messageData`` frame
with the schema the server advertised for its channel — protobuf messages through Google's
protobuf runtime built from the advertised ``FileDescriptorSet`` (not through this
project's codecs), JSON messages with :func:`json.loads`. The tests, ``bench_live`` and
``python -m tools.live_snapshot`` (the picture in docs/foxglove.md) use it.

Needs the ``websockets`` and ``protobuf`` packages (the ``dev`` extra).
"""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import time
from dataclasses import dataclass, field
from typing import Any

#: The WebSocket subprotocol of the Foxglove SDK's server.
SUBPROTOCOL = "foxglove.sdk.v1"
_MESSAGE_DATA = 0x01


@dataclass(frozen=True)
class Received:
    """One message a client received: its topic, log time (ns), schema name and decoded value
    (a protobuf message object or a JSON value), and the raw payload."""

    topic: str
    log_time: int
    schema: str
    value: Any
    payload: bytes
    received: float


@dataclass
class Probe:
    """A connected client (use :func:`connect`)."""

    ws: Any
    server_info: dict[str, Any]
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    _subs: dict[int, int] = field(default_factory=dict)
    _classes: dict[int, Any] = field(default_factory=dict)

    @property
    def topics(self) -> dict[str, dict[str, Any]]:
        return {c["topic"]: c for c in self.channels.values()}

    async def _read_control(self, timeout: float) -> None:
        """Read text frames until the channels are advertised (or ``timeout``)."""
        end = time.monotonic() + timeout
        while not self.channels and time.monotonic() < end:
            frame = await asyncio.wait_for(self.ws.recv(), max(0.01, end - time.monotonic()))
            if isinstance(frame, str):
                self._control(json.loads(frame))

    def _control(self, msg: dict[str, Any]) -> None:
        if msg.get("op") == "advertise":
            for ch in msg["channels"]:
                self.channels[int(ch["id"])] = ch
        elif msg.get("op") == "unadvertise":
            for cid in msg.get("channelIds", ()):
                self.channels.pop(int(cid), None)

    async def subscribe(self, topics: list[str] | None = None) -> list[str]:
        """Subscribe to ``topics`` (default: every advertised one); returns the topics subscribed.

        Raises:
            KeyError: a topic is not advertised.
        """
        by_topic = self.topics
        wanted = list(by_topic) if topics is None else topics
        subs = []
        for topic in wanted:
            ch = by_topic[topic]
            sid = len(self._subs) + 1
            self._subs[sid] = int(ch["id"])
            subs.append({"id": sid, "channelId": int(ch["id"])})
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        return wanted

    def _decoder(self, channel_id: int) -> Any:
        if channel_id not in self._classes:
            self._classes[channel_id] = _make_decoder(self.channels[channel_id])
        return self._classes[channel_id]

    async def receive(self, timeout: float) -> Received | None:
        """The next data message (None after ``timeout`` seconds without one)."""
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return None
            try:
                frame = await asyncio.wait_for(self.ws.recv(), left)
            except TimeoutError:
                return None
            if isinstance(frame, str):
                self._control(json.loads(frame))
                continue
            if not frame or frame[0] != _MESSAGE_DATA:
                continue
            sid, log_time = struct.unpack_from("<IQ", frame, 1)
            payload = bytes(frame[13:])
            cid = self._subs[sid]
            ch = self.channels[cid]
            return Received(
                ch["topic"], log_time, ch["schemaName"], self._decoder(cid)(payload), payload, time.time()
            )

    async def collect(
        self, topics: set[str], timeout: float, *, at_least: int = 1
    ) -> dict[str, list[Received]]:
        """Messages until each of ``topics`` has ``at_least`` of them (or ``timeout`` passes)."""
        got: dict[str, list[Received]] = {}
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(len(got.get(t, ())) >= at_least for t in topics):
                break
            r = await self.receive(end - time.monotonic())
            if r is None:
                break
            got.setdefault(r.topic, []).append(r)
        return got

    async def close(self) -> None:
        await self.ws.close()


async def connect(url: str, timeout: float = 5.0) -> Probe:
    """Connect to a Foxglove WebSocket server and read its advertised channels."""
    import websockets

    end = time.monotonic() + timeout
    while True:
        try:
            ws = await websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None)  # type: ignore[list-item]
            break
        except OSError:
            if time.monotonic() > end:
                raise
            await asyncio.sleep(0.05)
    info = json.loads(await asyncio.wait_for(ws.recv(), timeout))
    probe = Probe(ws, info)
    await probe._read_control(timeout)
    return probe


def _make_decoder(channel: dict[str, Any]) -> Any:
    encoding = channel["encoding"]
    if encoding == "json":
        return lambda data: json.loads(data)
    if encoding != "protobuf":
        raise ValueError(f"channel {channel['topic']}: no decoder for {encoding!r}")
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
    return cls.FromString
