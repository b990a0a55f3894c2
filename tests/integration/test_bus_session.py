"""Keys, bus configuration, and sessions that open, connect and close (real Zenoh on loopback)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from agent.bus.codecs import codec_for
from agent.bus.keys import (
    REQUEST_KEYS,
    STATE_KEYS,
    STREAMS,
    RobotKeys,
    default_robot_name,
    robot_name,
    spec_for_key,
    stream_key,
)
from agent.bus.session import BusConfig, BusError, bus_session, listening_endpoints, open_session
from agent.bus.testing import session_pair, settle, wait_until
from knowledge.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]


def test_robot_names_and_keys() -> None:
    assert robot_name(default_robot_name()) == default_robot_name()  # the host name is always usable
    assert robot_name(None) == default_robot_name()
    assert stream_key("rosie-2", "dialogue/intent") == "loci/rosie-2/dialogue/intent"
    keys = RobotKeys("rosie")
    assert (keys.scan, keys.all, keys.state("graph")) == (
        "loci/rosie/scan",
        "loci/rosie/**",
        "loci/rosie/state/graph",
    )
    for bad in ("a/b", "*", "ro bot", "-x", "x$y", "é"):
        with pytest.raises(ValueError, match="robot name"):
            robot_name(bad)
    for bad in ("", "scan/", "scan/**", "a//b", "sc*n"):
        with pytest.raises(ValueError, match="stream name"):
            stream_key("rosie", bad)
    assert spec_for_key("loci/rosie/graph/scene") is STREAMS["graph/scene"]
    assert spec_for_key("other/rosie/scan") is None


def test_every_stream_has_a_codec() -> None:
    for spec in STREAMS.values():
        assert codec_for(spec.schema).schema == spec.schema
        assert spec.name == stream_key("r", spec.name).split("/", 2)[2]


def test_the_docs_list_every_stream() -> None:
    doc = (REPO / "docs" / "bus.md").read_text()
    for spec in STREAMS.values():
        assert f"| `loci/<r>/{spec.name}` | `{spec.schema}` |" in doc, f"add {spec.name} to docs/bus.md"
    for name, schema in STATE_KEYS.items():
        assert f"| `loci/<r>/state/{name}` | `{schema}` |" in doc
    for name, (ask, answer) in REQUEST_KEYS.items():
        assert f"| `loci/<r>/{name}` | `{ask}` → `{answer}` |" in doc, f"add {name} to docs/bus.md"


def test_bus_config_checks_and_names_keys() -> None:
    cfg = BusConfig.from_mapping({"listen": ["tcp/127.0.0.1:7447"], "connect": ["tcp/10.0.0.2:7447"]})
    assert cfg.listen == ("tcp/127.0.0.1:7447",) and not cfg.picks_free_port
    assert BusConfig().picks_free_port and not BusConfig().multicast_scouting
    with pytest.raises(ConfigError, match="unknown key 'listen_on'"):
        BusConfig.from_mapping({"listen_on": []})
    with pytest.raises(ConfigError, match="not a Zenoh endpoint"):
        BusConfig(connect=("127.0.0.1:7447",))
    with pytest.raises(ConfigError, match="must be a list"):
        BusConfig.from_mapping({"connect": "tcp/127.0.0.1:7447"})
    with pytest.raises(ConfigError, match="router's endpoint"):
        BusConfig(mode="client", listen=())
    with pytest.raises(ConfigError, match="'peer' or 'client'"):
        BusConfig(mode="router")
    z = BusConfig().zenoh_config()
    assert json.loads(z.get_json("scouting/multicast/enabled")) is False
    assert json.loads(z.get_json("mode")) == "peer"


def test_a_free_port_is_resolved_and_a_taken_port_is_a_clear_error() -> None:
    with bus_session() as a:
        (endpoint,) = listening_endpoints(a)
        assert endpoint.startswith("tcp/127.0.0.1:") and not endpoint.endswith(":0")
        with pytest.raises(BusError, match="port already taken"):
            open_session(BusConfig(listen=(endpoint,)))
    assert a.is_closed()


def test_two_sessions_meet_and_close() -> None:
    with session_pair() as (a, b):
        assert str(a.zid()) in {str(z) for z in b.info.peers_zid()}
        got: list[bytes] = []
        sub = b.declare_subscriber("loci/t/x", lambda s: got.append(s.payload.to_bytes()))
        pub = a.declare_publisher("loci/t/x")
        settle(a, b)
        pub.put(b"hello")
        assert wait_until(lambda: got == [b"hello"])
        sub.undeclare()
    assert a.is_closed() and b.is_closed()


def test_bus_session_closes_when_the_block_fails() -> None:
    with pytest.raises(RuntimeError, match="boom"), bus_session() as s:
        raise RuntimeError("boom")
    assert s.is_closed()


def test_a_process_with_a_callback_subscriber_exits() -> None:
    """Zenoh keeps a process alive while a callback subscriber's session is open: ours closes it."""
    script = textwrap.dedent(
        """
        import asyncio
        from agent.bus.bridge import subscribe
        from agent.bus.codecs import LASER_SCAN_CODEC
        from agent.bus.session import bus_session

        KEEP = []  # references alive at exit, as in a real program: only closing lets it end

        async def main():
            with bus_session() as session:
                KEEP.append((session, subscribe(session, "loci/exit-test/scan", LASER_SCAN_CODEC)))
                await asyncio.sleep(0.05)
                print("subscribed", flush=True)

        asyncio.run(main())
        print("done", flush=True)
        """
    )
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=30, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["subscribed", "done"]
    assert time.monotonic() - t0 < 30


def test_config_file_is_the_base_and_the_typed_keys_go_over_it(tmp_path: Path) -> None:
    f = tmp_path / "agent.json5"
    f.write_text(
        '{ mode: "client", transport: { auth: { usrpwd: { user: "agent", password: "s3cret" } } } }',
        encoding="utf-8",
    )
    cfg = BusConfig(mode="peer", listen=("tcp/127.0.0.1:0",), config_file=str(f)).zenoh_config()
    assert json.loads(cfg.get_json("transport/auth/usrpwd/user")) == "agent"
    assert json.loads(cfg.get_json("mode")) == "peer"  # the typed key wins over the file
    with bus_session(BusConfig(listen=("tcp/127.0.0.1:0",), config_file=str(f))) as session:
        assert listening_endpoints(session)


def test_a_bad_config_file_is_a_config_error_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "nope.json5"
    with pytest.raises(ConfigError, match=r"nope\.json5"):
        BusConfig(config_file=str(missing)).zenoh_config()
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad\.json5"):
        BusConfig(config_file=str(bad)).zenoh_config()
