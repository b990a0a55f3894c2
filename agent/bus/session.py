"""Opening and closing Zenoh sessions from a typed :class:`BusConfig`.

By default a process opens an embedded **peer** session (no router), with multicast
scouting **off** (it fails in containers and floods real networks) and one explicit listen
endpoint on loopback. Port 0 means "any free port": the port the system chose is read back
from the session's admin space (:func:`listening_endpoints`); for that the admin space is
enabled read-only, and only when a port 0 is configured. Other processes reach the agent by
``connect`` endpoints (``tcp/127.0.0.1:7447``); peers that cannot connect yet keep retrying
in the background. With a router, use ``mode="client"`` and ``connect=[router endpoint]``.

Zenoh 1.x has no asyncio API and a process with a callback subscriber does not exit until
its session is closed: always use :func:`bus_session` (closes in ``finally``) or close the
session yourself in ``finally`` (not ``atexit``).
"""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import zenoh

from knowledge.errors import ConfigError, LociError

log = logging.getLogger(__name__)

#: The endpoint the agent listens on by convention, and where ``loci record`` connects by default.
DEFAULT_AGENT_ENDPOINT = "tcp/127.0.0.1:7447"
_ENDPOINT = re.compile(r"(tcp|udp|tls|quic|ws|unixsock-stream|unixpipe|serial|vsock)/\S+")


class BusError(LociError, OSError):
    """The Zenoh session could not be opened or answered with an error."""


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the bus.

    Attributes:
        mode: ``"peer"`` (default: talk directly to the peers named in ``connect`` and to those
            that connect to us) or ``"client"`` (everything through the router in ``connect``).
        listen: endpoints to accept connections on (peer mode only); port 0 picks a free port.
        connect: endpoints to connect to (other peers, or a router); retried in the background.
        multicast_scouting: find peers by UDP multicast (off: it fails in containers).
        config_file: a Zenoh JSON5 configuration to start from (user/password, TLS, access
            control: see deploy/zenoh/); mode, endpoints and scouting above are set over it.
    """

    mode: str = field(default="peer", metadata={"env": "LOCI_BUS_MODE"})
    listen: tuple[str, ...] = field(default=("tcp/127.0.0.1:0",), metadata={"env": "LOCI_BUS_LISTEN"})
    connect: tuple[str, ...] = field(default=(), metadata={"env": "LOCI_BUS_CONNECT"})
    multicast_scouting: bool = False
    config_file: str | None = field(default=None, metadata={"env": "LOCI_BUS_CONFIG_FILE"})

    def __post_init__(self) -> None:
        object.__setattr__(self, "listen", tuple(self.listen))
        object.__setattr__(self, "connect", tuple(self.connect))
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"bus.mode must be 'peer' or 'client', got {self.mode!r}")
        for key, endpoints in (("listen", self.listen), ("connect", self.connect)):
            for ep in endpoints:
                if not isinstance(ep, str) or not _ENDPOINT.fullmatch(ep):
                    raise ConfigError(
                        f"bus.{key}: {ep!r} is not a Zenoh endpoint; write PROTOCOL/ADDRESS, "
                        "e.g. 'tcp/127.0.0.1:7447'"
                    )
        if self.config_file is not None and not isinstance(self.config_file, str):
            raise ConfigError("bus.config_file must be the path of a Zenoh JSON5 file")
        if self.mode == "client" and self.listen:
            raise ConfigError("bus.listen must be empty in client mode (clients do not accept connections)")
        if self.mode == "client" and not self.connect and not self.multicast_scouting:
            raise ConfigError(
                "bus.connect must name the router's endpoint in client mode, e.g. 'tcp/10.0.0.1:7447'"
            )

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], where: str = "bus") -> BusConfig:
        """Build from a TOML table (:func:`agent.tables.build_dataclass`): unknown keys and
        values of the wrong type are a :class:`ConfigError` naming the key."""
        from agent.tables import build_dataclass

        return build_dataclass(cls, values, where)

    @property
    def picks_free_port(self) -> bool:
        """True when a listen endpoint has port 0 (the system picks a free port)."""
        return any(re.search(r":0(\D|$)", ep) for ep in self.listen)

    def zenoh_config(self) -> zenoh.Config:
        """The :class:`zenoh.Config` of this configuration."""
        cfg = zenoh.Config() if self.config_file is None else self._load_file(self.config_file)
        cfg.insert_json5("mode", json.dumps(self.mode))
        cfg.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast_scouting))
        cfg.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        cfg.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.picks_free_port:
            cfg.insert_json5("adminspace/enabled", "true")
            cfg.insert_json5("adminspace/permissions", json.dumps({"read": True, "write": False}))
        return cfg

    @staticmethod
    def _load_file(path: str) -> zenoh.Config:
        try:
            return zenoh.Config.from_file(path)
        except (zenoh.ZError, OSError) as exc:
            raise ConfigError(
                f"bus.config_file: cannot use {path!r} as a Zenoh configuration: {exc}"
            ) from exc


def open_session(config: BusConfig | None = None) -> zenoh.Session:
    """Open a Zenoh session; the caller must ``close()`` it in ``finally``.

    Raises:
        BusError: Zenoh refused the configuration or could not listen (port taken, ...).
    """
    config = config or BusConfig()
    try:
        session = zenoh.open(config.zenoh_config())
    except zenoh.ZError as exc:
        raise BusError(
            f"cannot open a Zenoh {config.mode} session (listen {list(config.listen)}, connect "
            f"{list(config.connect)}): {exc}; is the port already taken?"
        ) from exc
    log.debug("zenoh %s session %s opened", config.mode, session.zid())
    return session


@contextmanager
def bus_session(config: BusConfig | None = None) -> Iterator[zenoh.Session]:
    """``with bus_session(cfg) as session:`` — the session is closed however the block ends."""
    session = open_session(config)
    try:
        yield session
    finally:
        close_session(session)


def close_session(session: zenoh.Session) -> None:
    """Close a session (idempotent); errors while closing are logged, not raised."""
    try:
        if not session.is_closed():
            session.close()
    except zenoh.ZError as exc:  # pragma: no cover - closing twice races in Zenoh
        log.warning("closing the Zenoh session failed: %s", exc)


def listening_endpoints(session: zenoh.Session, timeout: float = 2.0) -> list[str]:
    """The endpoints the session really listens on (ports resolved), from its admin space.

    Needs the admin space, which :class:`BusConfig` enables when it asks for port 0; returns
    ``[]`` when it is off.
    """
    zid = session.zid()
    for reply in session.get(f"@/{zid}/*", timeout=timeout):
        sample = reply.ok
        if sample is None or str(sample.key_expr).rsplit("/", 1)[-1] not in ("peer", "router", "client"):
            continue
        try:
            info = json.loads(sample.payload.to_bytes())
        except ValueError:
            continue
        if isinstance(info, dict) and isinstance(info.get("locators"), list):
            return [str(x) for x in info["locators"]]
    return []
