"""deploy/: the robot configuration, the Zenoh router's authentication and access control
(for real, on loopback), the systemd units, the udev rule and their documentation."""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import shutil
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from agent.bus.session import BusConfig, close_session, listening_endpoints, open_session
from agent.cli import build_parser
from agent.config import LMS_VARIANTS, load_config
from knowledge.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
DEPLOY = REPO / "deploy"
ROBOT_TOML = DEPLOY / "robot.toml"
ZENOH = DEPLOY / "zenoh"
SYSTEMD = DEPLOY / "systemd"
UDEV_RULE = DEPLOY / "udev" / "99-loci-lms.rules"
DOC = REPO / "docs" / "deploy.md"

#: Where docs/deploy.md installs the files of deploy/ on the robot.
INSTALLED = {
    "/etc/loci/robot.toml": ROBOT_TOML,
    "/etc/loci/zenoh/router.json5": ZENOH / "router.json5",
    "/etc/loci/zenoh/agent.json5": ZENOH / "agent.json5",
    "/etc/loci/zenoh/dialogue.json5": ZENOH / "dialogue.json5",
    "/etc/loci/zenoh/tools.json5": ZENOH / "tools.json5",
    "/etc/loci/zenoh/credentials.txt": ZENOH / "credentials.txt.example",
}
VENV_LOCI = "/opt/loci/venv/bin/loci"


def installed(path: str) -> Path:
    """The file of deploy/ that docs/deploy.md installs at ``path`` on the robot."""
    assert path in INSTALLED, f"{path} is not a file deploy/ provides (known: {sorted(INSTALLED)})"
    return INSTALLED[path]


def zenoh_json(path: Path) -> dict[str, Any]:
    """A Zenoh JSON5 configuration file as Zenoh itself reads it (all defaults filled in)."""
    cfg = zenoh.Config.from_file(str(path))
    result: dict[str, Any] = json.loads(str(cfg))
    return result


def credentials() -> dict[str, str]:
    lines = (ZENOH / "credentials.txt.example").read_text().splitlines()
    return dict(line.split(":", 1) for line in lines if line.strip())


# ---------------------------------------------------------------------------- robot.toml


def pending_keys() -> list[str]:
    """Keys deploy/robot.toml uses that the agent's configuration does not know yet."""
    known_bus = set(BusConfig.__dataclass_fields__)
    table = tomllib.loads(ROBOT_TOML.read_text())
    return [f"bus.{k}" for k in table.get("bus", {}) if k not in known_bus]


def robot_table() -> dict[str, Any]:
    """deploy/robot.toml without the keys the configuration does not know yet."""
    table = tomllib.loads(ROBOT_TOML.read_text())
    for dotted in pending_keys():
        section, key = dotted.split(".")
        del table[section][key]
    return table


def test_robot_toml_loads_as_written() -> None:
    missing = pending_keys()
    if missing:
        pytest.skip(
            f"agent.config does not know {', '.join(missing)} yet (BusConfig needs a config_file "
            "field: the Zenoh JSON5 file with the process's user and password)"
        )
    config = load_config(ROBOT_TOML, env={})
    assert installed(dataclasses.asdict(config.bus)["config_file"]) == ZENOH / "agent.json5"


def test_robot_toml_describes_an_lms291_and_a_usb_camera() -> None:
    config = load_config(table=robot_table(), env={})
    assert config.laser.source == "lms"
    assert config.laser.port == "/dev/ttyUSB0"
    assert config.laser.baud == 500000
    assert config.laser.variant in LMS_VARIANTS
    assert config.camera.source in ("0", "/dev/video0")
    assert config.state.dir == "/var/lib/loci"
    assert config.conceptual.on
    for path in (config.conceptual.state, config.objects.database):
        assert Path(path).is_relative_to("/var/lib/loci"), path
    assert config.robot_name == "rosie"


def test_robot_toml_is_a_client_of_the_router() -> None:
    config = load_config(table=robot_table(), env={})
    router = zenoh_json(ZENOH / "router.json5")
    assert config.bus.mode == "client"
    assert config.bus.listen == ()
    assert list(config.bus.connect) == router["listen"]["endpoints"]


def test_robot_toml_rejects_a_typo_like_the_real_file_would() -> None:
    # the loading test above means something only if a wrong key in this file is refused
    table = robot_table()
    table["laser"]["prot"] = table["laser"].pop("port")
    with pytest.raises(ConfigError, match="prot"):
        load_config(table=table, env={})


def test_robot_toml_explains_every_key() -> None:
    text = ROBOT_TOML.read_text()
    assert "/dev/lms" in text, "the comments must recommend the udev link /dev/lms"
    # every key sits in a block of key lines that starts right below a comment line
    key = re.compile(r"[a-z_]+\s*=")
    previous = ""
    unexplained = []
    for line in text.splitlines():
        stripped = line.strip()
        if key.match(stripped) and not (previous.startswith("#") or key.match(previous)):
            unexplained.append(stripped)
        previous = stripped
    assert not unexplained, f"keys without a comment above them: {unexplained}"


# ---------------------------------------------------------------------------- Zenoh


def test_zenoh_files_parse_and_agree() -> None:
    router = zenoh_json(ZENOH / "router.json5")
    assert router["mode"] == "router"
    assert router["transport"]["auth"]["usrpwd"]["dictionary_file"] == "/etc/loci/zenoh/credentials.txt"
    installed(router["transport"]["auth"]["usrpwd"]["dictionary_file"])
    acl = router["access_control"]
    assert acl["enabled"] is True
    assert acl["default_permission"] == "deny"
    users = credentials()
    in_subjects = [u for s in acl["subjects"] for u in s["usernames"]]
    assert sorted(in_subjects) == sorted(users), "each user must be in exactly one subject"
    for name, user in (("agent.json5", "agent"), ("dialogue.json5", "dialogue"), ("tools.json5", "tools")):
        client = zenoh_json(ZENOH / name)
        assert client["mode"] == "client"
        assert client["connect"]["endpoints"] == router["listen"]["endpoints"]
        usrpwd = client["transport"]["auth"]["usrpwd"]
        assert usrpwd["user"] == user
        assert users[user] == usrpwd["password"], f"{name}: the password must match credentials.txt"


def _router_session() -> tuple[zenoh.Session, str]:
    """The router of deploy/zenoh/router.json5 on a free loopback port, with the example
    credentials; returns the session and its endpoint."""
    cfg = zenoh.Config.from_file(str(ZENOH / "router.json5"))
    cfg.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"]))
    cfg.insert_json5(
        "transport/auth/usrpwd/dictionary_file", json.dumps(str(ZENOH / "credentials.txt.example"))
    )
    cfg.insert_json5("adminspace/enabled", "true")
    session = zenoh.open(cfg)
    try:
        endpoints = [e for e in listening_endpoints(session) if e.startswith("tcp/127.0.0.1:")]
    except BaseException:
        close_session(session)
        raise
    assert endpoints, "the router does not say where it listens"
    return session, endpoints[0]


def _client(
    endpoint: str, config_file: str, user: str | None = None, password: str | None = None
) -> zenoh.Session:
    cfg = zenoh.Config.from_file(str(ZENOH / config_file))
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    if user is not None:
        cfg.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        cfg.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return zenoh.open(cfg)


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    session, endpoint = _router_session()
    try:
        yield endpoint
    finally:
        close_session(session)


class Inbox:
    """What a subscriber on ``loci/r/**`` received: (key, payload) pairs."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, bytes]] = []
        self._cond = threading.Condition()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.samples.append((str(sample.key_expr), sample.payload.to_bytes()))
            self._cond.notify_all()

    def wait_for(self, pred: Callable[[list[tuple[str, bytes]]], bool], timeout: float = 5.0) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: pred(self.samples), timeout)


#: What each user may publish (put), as docs/deploy.md's table says: loci/<robot>/<stream>.
MAY_PUBLISH: dict[str, set[str]] = {
    "agent": {
        "scan",
        "scan/full",
        "tf",
        "tf/map",
        "place",
        "graph",
        "graph/scene",
        "areas",
        "areas/scene",
        "diagnostics",
        "people",
        "people/scene",
        "objects",
        "map/edit",
        "localization/pose",
        "localization/status",
        "localization/scene",
        "dialogue/say",
        "dialogue/ask",
        "base/cmd",
        "base/goal",
    },
    "dialogue": {"dialogue/intent"},
    "speech": {"dialogue/heard"},
    "base": {"odom", "base/status", "scan", "camera", "sim/truth", "pose/truth"},
    "tools": set(),
}
#: Wildcard puts that once reached the agent's intent subscriber (issue 18, failure 4).
WILDCARD_PUTS = [
    "loci/r/dialogue/*",
    "loci/r/**",
    "loci/r/dialogue/intent/**",
    "**",
    "loci/**",
    "loci/r/*/*",
]


def _user(endpoint: str, user: str) -> zenoh.Session:
    return _client(endpoint, "agent.json5", user, credentials()[user])


def test_each_user_publishes_only_its_keys_and_wildcard_puts_reach_nothing(router: str) -> None:
    from agent.bus.keys import STREAMS

    assert set(MAY_PUBLISH) == set(credentials())
    assert set().union(*MAY_PUBLISH.values()) == set(STREAMS), "every stream needs a publisher"
    keys = [f"loci/r/{s}" for s in sorted(STREAMS)] + WILDCARD_PUTS
    sessions: dict[str, zenoh.Session] = {}
    try:
        for user in MAY_PUBLISH:
            sessions[user] = _user(router, user)
        # witnesses: a reader of everything (a tool in a session of its own: a session hears
        # its own puts without the router) and the agent's own intent subscriber
        witness = sessions["witness"] = _user(router, "tools")
        inbox, intents = Inbox(), Inbox()
        subs = [
            witness.declare_subscriber("loci/**", inbox),
            sessions["agent"].declare_subscriber("loci/r/dialogue/intent", intents),
        ]
        deadline = time.monotonic() + 5.0
        while not inbox.samples and time.monotonic() < deadline:
            sessions["base"].put("loci/r/odom", b"ready?")
            time.sleep(0.05)
        assert inbox.samples, "no sample reached the subscriber through the router"
        # the agent's subscriber is declared too once one of the dialogue's intents arrives
        assert inbox.wait_for(
            lambda _: (sessions["dialogue"].put("loci/r/dialogue/intent", b"ready?") or intents.samples) != []
        )
        inbox.samples.clear()
        intents.samples.clear()
        for user in MAY_PUBLISH:
            session = sessions[user]
            for key in keys:
                session.put(key, f"{user} {key}".encode())
        # a session's samples arrive in order: once a user's last allowed put is in, the
        # others would be in too
        for user, allowed in MAY_PUBLISH.items():
            if allowed:
                last = f"loci/r/{max(allowed)}"
                assert inbox.wait_for(lambda s, u=user, k=last: (k, f"{u} {k}".encode()) in s), user
        time.sleep(0.3)  # for tools, which may publish nothing at all
        got = {p.decode() for _, p in inbox.samples if p != b"ready?"}
        want = {f"{u} loci/r/{s}" for u, streams in MAY_PUBLISH.items() for s in streams}
        assert got == want, f"got and must not: {sorted(got - want)}; missing: {sorted(want - got)}"
        # what reached the agent's intent subscriber from other sessions (its own session's
        # puts reach it without the router)
        others = [p for _, p in intents.samples if p != b"ready?" and not p.startswith(b"agent ")]
        assert others == [b"dialogue loci/r/dialogue/intent"]
        for sub in subs:
            sub.undeclare()
    finally:
        for s in reversed(sessions.values()):
            close_session(s)


def test_only_the_agent_answers_state_queries_and_a_huge_message_is_dropped(router: str) -> None:
    sessions: dict[str, zenoh.Session] = {}
    try:
        for user in ("agent", "dialogue", "tools", "base"):
            sessions[user] = _user(router, user)
        qs = [
            sessions[u].declare_queryable(
                "loci/r/state/graph", lambda q, u=u: q.reply(q.key_expr, u.encode())
            )
            for u in ("agent", "dialogue")
        ]
        deadline = time.monotonic() + 5.0
        answers: list[bytes] = []
        while not answers and time.monotonic() < deadline:
            answers = [
                r.ok.payload.to_bytes()
                for r in sessions["tools"].get("loci/r/state/graph", timeout=1.0)
                if r.ok
            ]
        assert answers == [b"agent"]
        # Zenoh's own limit (transport.link.rx.max_message_size): 16 MiB, not its default 1 GiB
        inbox = Inbox()
        sub = sessions["tools"].declare_subscriber("loci/r/camera", inbox)
        while not inbox.samples and time.monotonic() < deadline + 5.0:
            sessions["base"].put("loci/r/camera", b"small")
            time.sleep(0.05)
        block = zenoh.CongestionControl.BLOCK  # DROP (the default) could drop "after" behind the big one
        sessions["base"].put("loci/r/camera", b"x" * (17 << 20), congestion_control=block)
        sessions["base"].put("loci/r/camera", b"after", congestion_control=block)
        assert inbox.wait_for(lambda s: ("loci/r/camera", b"after") in s, timeout=15.0)
        assert max(len(p) for _, p in inbox.samples) < 1 << 20
        for q in qs:
            q.undeclare()
        sub.undeclare()
    finally:
        for s in reversed(sessions.values()):
            close_session(s)


def test_each_process_says_it_is_ready_under_its_own_role_only(router: str) -> None:
    """Ready tokens (agent/bus/ready.py) through the router: a reader sees the agent's, the
    dialogue's and the base's; a tool cannot pass itself off as the agent."""
    from agent.bus.ready import declare_ready, ready_roles

    sessions: dict[str, zenoh.Session] = {}
    try:
        for user in ("agent", "dialogue", "base", "tools"):
            sessions[user] = _user(router, user)
        tokens = [
            declare_ready(sessions["agent"], "r", "agent"),
            declare_ready(sessions["dialogue"], "r", "dialogue"),
            declare_ready(sessions["base"], "r", "sim"),
            declare_ready(sessions["tools"], "q", "agent"),  # refused by the router
        ]
        deadline = time.monotonic() + 5.0
        while (
            ready_roles(sessions["tools"], "r") != {"agent", "dialogue", "sim"}
            and time.monotonic() < deadline
        ):
            time.sleep(0.1)
        assert ready_roles(sessions["tools"], "r") == {"agent", "dialogue", "sim"}
        assert ready_roles(sessions["agent"], "q") == set()
        for t in tokens:
            t.undeclare()
    finally:
        for s in reversed(sessions.values()):
            close_session(s)


def test_the_dialogue_service_connects_as_the_dialogue_user(router: str) -> None:
    # the unit's LOCI_BUS_CONFIG_FILE once was read by no code: the dialogue process
    # connected as "agent" (robot.toml's config_file), which may not send intents
    unit = read_unit(SYSTEMD / "loci-dialogue.service")
    env = dict(v.split("=", 1) for v in values(unit, "Service", "Environment"))
    config = load_config(ROBOT_TOML, env=env)
    bus = dataclasses.replace(
        config.bus, connect=(router,), config_file=str(installed(str(config.bus.config_file)))
    )
    assert bus.config_file == str(ZENOH / "dialogue.json5")
    sessions = [_user(router, "tools")]
    try:
        inbox = Inbox()
        sessions[0].declare_subscriber("loci/r/dialogue/intent", inbox)
        dialogue = open_session(bus)
        sessions.append(dialogue)
        deadline = time.monotonic() + 5.0
        while not inbox.samples and time.monotonic() < deadline:
            dialogue.put("loci/r/dialogue/intent", b"from the dialogue service")
            time.sleep(0.05)
        assert inbox.samples, "the dialogue service's intents do not reach the agent"
    finally:
        for s in reversed(sessions):
            close_session(s)


def test_loci_record_logs_in_as_tools_and_records_through_the_router(router: str, tmp_path: Path) -> None:
    """The documented recording on a robot: ``loci record --mode client --zenoh-config tools.json5``."""
    from agent.recording.replay import McapMessages

    out = tmp_path / "run.mcap"
    agent = _user(router, "agent")
    stop = threading.Event()

    def publish() -> None:
        while not stop.is_set():
            agent.put("loci/r/diagnostics", b'{"from": "the agent"}')
            time.sleep(0.05)

    pub = threading.Thread(target=publish, daemon=True)
    pub.start()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "agent.cli", "record", str(out), "--robot", "r", "--mode", "client",
             "--connect", router, "--zenoh-config", str(ZENOH / "tools.json5"), "--duration", "3"],
            capture_output=True, text=True, timeout=60, cwd=REPO,
        )  # fmt: skip
    finally:
        stop.set()
        pub.join()
        close_session(agent)
    assert proc.returncode == 0, proc.stderr
    keys = {m.topic for m in McapMessages(out)}
    assert "loci/r/diagnostics" in keys


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def throwaway_ca(folder: Path) -> tuple[Path, Path, Path]:
    """A CA and a certificate for localhost/127.0.0.1 that it signed (EC P-256, one day):
    returns the CA certificate, the server's certificate and its key."""
    ec = ("-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes")
    _openssl(
        "req",
        "-x509",
        *ec,
        "-keyout",
        "ca.key",
        "-out",
        "ca.pem",
        "-days",
        "1",
        "-subj",
        "/CN=loci test CA",
        cwd=folder,
    )
    _openssl("req", *ec, "-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=localhost", cwd=folder)
    (folder / "ext.cnf").write_text(
        "subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\n"
        "keyUsage=digitalSignature\nextendedKeyUsage=serverAuth\n"
    )
    _openssl(
        "x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
        "-out", "server.pem", "-days", "1", "-extfile", "ext.cnf",
        cwd=folder,
    )  # fmt: skip
    return folder / "ca.pem", folder / "server.pem", folder / "server.key"


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is not installed")
def test_tls_router_with_its_certificate_on_loopback(tmp_path: Path) -> None:
    # docs/deploy.md, "TLS": the router listens on tls/ with its certificate and key; a client
    # names the CA that signed it (root_ca_certificate) and still logs in with its password
    (tmp_path / "good").mkdir()
    (tmp_path / "other").mkdir()
    ca, cert, key = throwaway_ca(tmp_path / "good")
    other_ca, _, _ = throwaway_ca(tmp_path / "other")
    cfg = zenoh.Config.from_file(str(ZENOH / "router.json5"))
    cfg.insert_json5("listen/endpoints", json.dumps(["tls/127.0.0.1:0"]))
    cfg.insert_json5(
        "transport/auth/usrpwd/dictionary_file", json.dumps(str(ZENOH / "credentials.txt.example"))
    )
    cfg.insert_json5("transport/link/tls/listen_certificate", json.dumps(str(cert)))
    cfg.insert_json5("transport/link/tls/listen_private_key", json.dumps(str(key)))
    cfg.insert_json5("adminspace/enabled", "true")
    router = zenoh.open(cfg)
    sessions: list[zenoh.Session] = []
    try:
        (port,) = {e.rsplit(":", 1)[1] for e in listening_endpoints(router) if e.startswith("tls/")}
        endpoint = f"tls/localhost:{port}"

        def client(user: str, root_ca: Path | None) -> zenoh.Session:
            c = zenoh.Config.from_file(str(ZENOH / "agent.json5"))
            c.insert_json5("connect/endpoints", json.dumps([endpoint]))
            c.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
            c.insert_json5("transport/auth/usrpwd/password", json.dumps(credentials()[user]))
            if root_ca is not None:
                c.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(root_ca)))
            session = zenoh.open(c)
            sessions.append(session)
            return session

        reader, base = client("tools", ca), client("base", ca)
        inbox = Inbox()
        reader.declare_subscriber("loci/r/odom", inbox)
        deadline = time.monotonic() + 5.0
        while not inbox.samples and time.monotonic() < deadline:
            base.put("loci/r/odom", b"over TLS")
            time.sleep(0.05)
        assert ("loci/r/odom", b"over TLS") in inbox.samples
        # a client that does not trust the router's CA, or trusts another, cannot connect
        for root_ca in (None, other_ca):
            with pytest.raises(zenoh.ZError):
                client("base", root_ca)
        # nor a plain TCP client on the TLS port
        with pytest.raises(zenoh.ZError):
            _client(f"tcp/127.0.0.1:{port}", "agent.json5")
    finally:
        for s in reversed(sessions):
            close_session(s)
        close_session(router)


@pytest.mark.parametrize(
    ("user", "password"),
    [("tools", "not the password"), ("nobody", "CHANGE-ME-tools"), (None, None)],
    ids=["wrong-password", "unknown-user", "no-credentials"],
)
def test_the_router_refuses_bad_credentials(router: str, user: str | None, password: str | None) -> None:
    cfg = zenoh.Config.from_file(str(ZENOH / "agent.json5"))
    cfg.insert_json5("connect/endpoints", json.dumps([router]))
    if user is None:
        cfg.insert_json5("transport/auth/usrpwd", json.dumps({"user": None, "password": None}))
    else:
        cfg.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        cfg.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    with pytest.raises(zenoh.ZError):
        session = zenoh.open(cfg)
        close_session(session)  # pragma: no cover - only when the router let it in


# ---------------------------------------------------------------------------- systemd


def read_unit(path: Path) -> dict[str, list[tuple[str, str]]]:
    """A systemd unit as {section: [(key, value), ...]} (keys may repeat, as in systemd)."""
    sections: dict[str, list[tuple[str, str]]] = {}
    current: list[tuple[str, str]] | None = None
    for n, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1], [])
            continue
        assert current is not None, f"{path.name}:{n}: a setting before any [Section]"
        assert "=" in line, f"{path.name}:{n}: not KEY=VALUE: {line!r}"
        key, value = line.split("=", 1)
        current.append((key.strip(), value.strip()))
    return sections


def values(unit: dict[str, list[tuple[str, str]]], section: str, key: str) -> list[str]:
    return [v for k, v in unit.get(section, []) if k == key]


def one(unit: dict[str, list[tuple[str, str]]], section: str, key: str) -> str:
    found = values(unit, section, key)
    assert len(found) == 1, f"[{section}] {key}: expected one value, got {found}"
    return found[0]


UNITS = ["loci-agent.service", "loci-dialogue.service", "zenohd.service"]


@pytest.mark.parametrize("name", UNITS)
def test_unit_runs_as_a_service_user_and_restarts(name: str) -> None:
    unit = read_unit(SYSTEMD / name)
    assert set(unit) == {"Unit", "Service", "Install"}
    assert one(unit, "Service", "Restart") == "on-failure"
    user = one(unit, "Service", "User")
    assert user not in ("root", "0", "")
    assert one(unit, "Service", "KillSignal") in ("SIGINT", "SIGTERM")
    for key in ("Wants", "After"):
        assert "network-online.target" in " ".join(values(unit, "Unit", key)).split()
    assert one(unit, "Install", "WantedBy") == "multi-user.target"


@pytest.mark.parametrize("name", ["loci-agent.service", "loci-dialogue.service"])
def test_loci_units_start_after_the_router_and_run_the_console_script(name: str) -> None:
    unit = read_unit(SYSTEMD / name)
    assert "zenohd.service" in " ".join(values(unit, "Unit", "After")).split()
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    assert "loci" in scripts
    argv = one(unit, "Service", "ExecStart").split()
    assert argv[0] == VENV_LOCI
    config = argv[argv.index("--config") + 1]
    installed(config)
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    if argv[1] not in commands:
        pytest.skip(f"`loci {argv[1]}` does not exist yet (its unit is ready for it)")
    args = parser.parse_args(argv[1:])
    assert args.config == Path(config)


def test_agent_unit_has_the_devices_and_the_state_dir() -> None:
    unit = read_unit(SYSTEMD / "loci-agent.service")
    groups = " ".join(values(unit, "Service", "SupplementaryGroups")).split()
    assert {"dialout", "video"} <= set(groups)
    assert one(unit, "Service", "StateDirectory") == "loci"  # /var/lib/loci, robot.toml's state.dir
    assert load_config(table=robot_table(), env={}).state.dir == "/var/lib/loci"


def test_dialogue_unit_uses_its_own_zenoh_user() -> None:
    unit = read_unit(SYSTEMD / "loci-dialogue.service")
    env = dict(v.split("=", 1) for v in values(unit, "Service", "Environment"))
    assert installed(env["LOCI_BUS_CONFIG_FILE"]) == ZENOH / "dialogue.json5"
    assert one(unit, "Service", "User") != one(read_unit(SYSTEMD / "loci-agent.service"), "Service", "User")


def test_router_unit_runs_zenohd_with_the_router_config() -> None:
    argv = one(read_unit(SYSTEMD / "zenohd.service"), "Service", "ExecStart").split()
    assert Path(argv[0]).name == "zenohd"
    assert installed(argv[argv.index("--config") + 1]) == ZENOH / "router.json5"


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed")
def test_units_pass_systemd_analyze_verify(tmp_path: Path) -> None:
    # the binaries exist only on the robot: point them at real executables here
    for name in UNITS:
        text = (SYSTEMD / name).read_text()
        text = text.replace(VENV_LOCI, str(Path(sys.executable).parent / "loci"))
        text = text.replace("/usr/bin/zenohd", shutil.which("true") or "/bin/true")
        (tmp_path / name).write_text(text)
    proc = subprocess.run(
        ["systemd-analyze", "verify", "--man=no", *(str(tmp_path / n) for n in UNITS)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    # parse errors are warnings ("ignoring") with exit code 0: fail on any line about our units
    ours = [line for line in (proc.stdout + proc.stderr).splitlines() if any(n in line for n in UNITS)]
    assert proc.returncode == 0 and not ours, proc.stdout + proc.stderr


# ---------------------------------------------------------------------------- udev

_TOKEN = re.compile(r'\s*([A-Z_]+(?:\{[A-Za-z0-9_]+\})?)\s*(==|!=|\+=|-=|:=|=)\s*"([^"]*)"\s*(?:,|$)')


def udev_rules() -> list[dict[str, tuple[str, str]]]:
    """The rules of the file: {KEY: (operator, value)} each; a malformed token fails."""
    rules = []
    for n, line in enumerate(UDEV_RULE.read_text().splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        rule: dict[str, tuple[str, str]] = {}
        pos = 0
        while pos < len(line):
            m = _TOKEN.match(line, pos)
            assert m, f"{UDEV_RULE.name}:{n}: cannot parse from {line[pos:]!r}"
            rule[m.group(1)] = (m.group(2), m.group(3))
            pos = m.end()
        rules.append(rule)
    return rules


def test_udev_rule_names_the_scanner_adapters() -> None:
    rules = udev_rules()
    ids = {(r["ATTRS{idVendor}"][1], r["ATTRS{idProduct}"][1]) for r in rules}
    assert {("0403", "6001"), ("067b", "2303"), ("10c4", "ea60")} <= ids
    for rule in rules:
        assert rule["SUBSYSTEM"] == ("==", "tty")
        assert rule["ATTRS{idVendor}"][0] == rule["ATTRS{idProduct}"][0] == "=="
        assert rule["SYMLINK"] == ("+=", "lms")
        assert rule["GROUP"] == ("=", "dialout")
        assert "ATTRS{serial}" in rule, "each rule must pin the adapter's serial number"
    assert "udevadm info" in UDEV_RULE.read_text()


# ---------------------------------------------------------------------------- docs


def test_docs_cover_every_deploy_file() -> None:
    doc = DOC.read_text()
    files = [p for p in DEPLOY.rglob("*") if p.is_file() and p.name != "README.md"]
    missing = [str(p.relative_to(REPO)) for p in files if str(p.relative_to(REPO)) not in doc]
    assert not missing, f"docs/deploy.md does not mention {missing}"
    for named in set(re.findall(r"deploy/[\w./-]+\w", doc)):
        assert (REPO / named).exists(), f"docs/deploy.md names {named}, which does not exist"
    for path in INSTALLED:
        assert path in doc, f"docs/deploy.md does not say what goes to {path}"


def test_docs_table_of_users_is_what_the_router_enforces() -> None:
    # the table in docs/deploy.md, section 6: user -> keys it may publish (the wire test above
    # checks MAY_PUBLISH against the router)
    rows = re.findall(r"^\| `(\w+)` \| [^|]+ \| ([^|]+) \| ([^|]+) \|$", DOC.read_text(), re.MULTILINE)
    table = {user: set(re.findall(r"`([\w/]+)`", publish)) - {"state/*"} for user, publish, _ in rows}
    assert table == MAY_PUBLISH
    assert all(sub.strip() == "`loci/**`" for _, _, sub in rows)
