"""The agent's TOML configuration: defaults, types, unknown keys, precedence, docs."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from agent.bus.session import DEFAULT_AGENT_ENDPOINT
from agent.config import ENV_VARS, AgentConfig, load_config
from agent.core.pipeline import PipelineParams
from knowledge.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]

FULL = """
[robot]
name = "rosie"

[bus]
listen = ["tcp/127.0.0.1:7450"]
connect = ["tcp/10.0.0.2:7447"]

[laser]
port = "/dev/ttyUSB0"
baud = 38400
variant = "180/1"
frame_id = "front_laser"
queue_size = 8
timeout = 0.5

[laser.mount]
x = 0.2
y = -0.05
yaw = 90

[odometry]
max_wait = 0.3
max_gap = 1.0

[places]
model = "models/office.npz"
window = 7

[navigation]
node_distance = 1.5
door_merge = 0.5
ignore_labels = ["doorway", "unknown"]

[navigation.doorways]
min_width = 0.6
max_width = 1.4

[local_map]
radius = 15.0
max_points = 4000

[rear_beams]
hit_radius = 0.1
front = "min"

[state]
dir = "state"
save_interval = 5

[record]
path = "runs/%Y%m%d.mcap"
flush_interval = 0.5

[diagnostics]
period = 2.0

[camera]
source = "/dev/video0"
width = 800
height = 600
fps = 15

[conceptual]
state = "concepts/map.sqlite3"
ontologies = ["extra.owl", "/abs/more.owl"]
java = "/usr/bin/java"
debounce = 0.5

[objects]
database = "objects"
min_inliers = 20

[follow]
distance = 1.5
lost_after = 3
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "robot.toml"
    p.write_text(text)
    return p


def test_every_key_of_a_full_file_lands_in_its_field(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, FULL), env={})
    assert cfg.robot_name == "rosie"
    assert cfg.bus.listen == ("tcp/127.0.0.1:7450",) and cfg.bus.connect == ("tcp/10.0.0.2:7447",)
    assert cfg.laser.source == "lms" and cfg.laser.port == "/dev/ttyUSB0" and cfg.laser.baud == 38400
    assert cfg.laser.angle_resolution == (180, 1.0)
    assert (cfg.laser.frame_id, cfg.laser.queue_size, cfg.laser.timeout) == ("front_laser", 8, 0.5)
    assert cfg.laser.mount.pose == pytest.approx((0.2, -0.05, math.pi / 2))
    assert (cfg.odometry.max_wait, cfg.odometry.max_gap) == (0.3, 1.0)
    # relative paths are relative to the file's folder
    assert Path(cfg.places.model) == tmp_path / "models" / "office.npz"
    assert cfg.state.path == tmp_path / "state" / "navgraph.json" and cfg.state.save_interval == 5.0
    assert cfg.record.path == str(tmp_path / "runs" / "%Y%m%d.mcap") and cfg.record.flush_interval == 0.5
    # the core's own parameter classes, typed (an integer TOML value becomes a float)
    assert cfg.navigation.node_distance == 1.5 and cfg.navigation.window == 7
    assert cfg.navigation.ignore_labels == ("doorway", "unknown")
    assert (cfg.doorways.min_width, cfg.doorways.max_width) == (0.6, 1.4)
    assert (cfg.local_map.radius, cfg.local_map.max_points) == (15.0, 4000)
    assert cfg.rear_beams.hit_radius == 0.1 and cfg.rear_beams.front == "min"
    assert cfg.diagnostics.period == 2.0
    assert (cfg.camera.source, cfg.camera.width, cfg.camera.height, cfg.camera.fps) == (
        "/dev/video0",
        800,
        600,
        15.0,
    )
    # a [conceptual] section turns the conceptual map on; its paths are relative to the file
    assert cfg.conceptual.on and cfg.conceptual.java == "/usr/bin/java" and cfg.conceptual.debounce == 0.5
    assert Path(cfg.conceptual.state) == tmp_path / "concepts" / "map.sqlite3"
    assert cfg.conceptual.ontologies == (str(tmp_path / "extra.owl"), "/abs/more.owl")
    assert Path(cfg.objects.database) == tmp_path / "objects" and cfg.objects.min_inliers == 20
    assert (cfg.follow.distance, cfg.follow.lost_after) == (1.5, 3.0)
    params = PipelineParams.from_config(cfg)
    assert PipelineParams.from_table(params.to_table()) == params


def test_defaults_without_a_file() -> None:
    cfg = load_config(env={"XDG_STATE_HOME": "/var/lib/x"})
    assert cfg == load_config(table={}, env={"XDG_STATE_HOME": "/var/lib/x"})
    assert cfg.laser.source == "bus" and cfg.laser.port is None
    assert cfg.bus.mode == "peer" and cfg.bus.listen == (DEFAULT_AGENT_ENDPOINT,)
    assert cfg.odometry.source == "bus" and cfg.odometry.max_wait == 0.2
    assert cfg.navigation.node_distance == 1.0 and cfg.navigation.window == 10
    assert cfg.places.model == "default" and cfg.places.model_path.is_file()
    assert cfg.state.path == Path("/var/lib/x/genius-loci") / cfg.robot_name / "navgraph.json"
    assert cfg.record.path is None
    # no [conceptual] section: no reasoner (it needs Java); its files default to the state folder
    assert not cfg.conceptual.on and cfg.conceptual.enabled is False
    assert Path(cfg.conceptual.state) == cfg.state.path.parent / "concepts.sqlite3"
    assert Path(cfg.objects.database) == cfg.state.path.parent / "objects"
    assert cfg.camera.source == "" and cfg.follow.distance == 1.0
    assert load_config(table={"conceptual": {}}, env={}).conceptual.on
    assert not load_config(table={"conceptual": {"enabled": False}}, env={}).conceptual.on
    # a router client does not get the agent's default listen endpoint
    client = load_config(table={"bus": {"mode": "client", "connect": ["tcp/10.0.0.1:7447"]}}, env={})
    assert client.bus.listen == ()


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"robots": {}}, r"unknown section \[robots\]"),
        ({"laser": {"prot": "/dev/ttyUSB0"}}, r"\[laser\]: unknown key 'prot'"),
        ({"laser": {"mount": {"z": 1.0}}}, r"\[laser.mount\]: unknown key 'z'"),
        ({"navigation": {"doorways": {"width": 1.0}}}, r"\[navigation.doorways\]: unknown key 'width'"),
        ({"navigation": {"window": 5}}, r"places.window"),
        ({"rear_beams": {"n_beams": 180}}, r"\[rear_beams\]: unknown key 'n_beams'"),
        ({"bus": {"listne": []}}, r"\[bus\]: unknown key 'listne'"),
        ({"navigation": {"node_distance": "1"}}, r"navigation.node_distance must be a number, got '1'"),
        ({"navigation": {"node_distance": True}}, r"navigation.node_distance must be a number"),
        ({"local_map": {"max_points": 2.5}}, r"local_map.max_points must be an integer"),
        ({"state": {"resume": "yes"}}, r"state.resume must be true or false"),
        ({"navigation": {"ignore_labels": "doorway"}}, r"navigation.ignore_labels must be a list"),
        ({"navigation": {"node_distance": -1.0}}, r"\[navigation\]: node_distance must be a positive"),
        ({"laser": {"variant": "270/0.5"}}, r"variant must be one of"),
        ({"laser": {"source": "lms"}}, r"needs 'port'"),
        ({"laser": {"source": "usb"}}, r"source must be 'lms'"),
        ({"laser": "ttyUSB0"}, r"laser must be a table"),
        ({"odometry": {"source": "wheels"}}, r"source must be 'bus'"),
        ({"robot": {"name": "has space"}}, r"cannot be part of a Zenoh key"),
        ({"camera": {"device": "0"}}, r"\[camera\]: unknown key 'device'"),
        ({"camera": {"width": 0}}, r"\[camera\]: width and height must be >= 1"),
        ({"camera": {"fps": "10"}}, r"camera.fps must be a number"),
        ({"conceptual": {"reasoner": "pellet"}}, r"\[conceptual\]: unknown key 'reasoner'"),
        ({"conceptual": {"ontologies": "my.owl"}}, r"conceptual.ontologies must be a list"),
        ({"conceptual": {"enabled": "yes"}}, r"conceptual.enabled must be true or false"),
        ({"conceptual": {"debounce": -1}}, r"debounce must be >= 0"),
        ({"objects": {"db": "x"}}, r"\[objects\]: unknown key 'db'"),
        ({"objects": {"min_inliers": 2}}, r"min_inliers must be >= 4"),
        ({"follow": {"distanse": 1.0}}, r"\[follow\]: unknown key 'distanse'"),
        ({"follow": {"lost_after": 0}}, r"lost_after must be > 0"),
    ],
)
def test_bad_settings_are_errors_that_name_the_key(table: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_config(table=table, env={})


def test_bad_toml_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(write(tmp_path, "[robot\nname = 1"), env={})
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_config(tmp_path / "absent.toml", env={})


def test_precedence_command_line_over_environment_over_file(tmp_path: Path) -> None:
    path = write(tmp_path, FULL)
    env = {
        "LOCI_ROBOT": "env-bot",
        "LOCI_STATE_DIR": "/env/state",
        "LOCI_BUS_CONNECT": "tcp/10.0.0.3:7447, tcp/10.0.0.4:7447",
        "LOCI_LASER_PORT": "",  # empty: unset
        "LOCI_RECORD": "env.mcap",
    }
    cfg = load_config(path, env=env)
    assert cfg.robot_name == "env-bot" and cfg.state.dir == "/env/state"
    assert cfg.bus.connect == ("tcp/10.0.0.3:7447", "tcp/10.0.0.4:7447")
    assert cfg.laser.port == "/dev/ttyUSB0"
    assert cfg.record.path == "env.mcap"  # from the environment: relative to the working directory
    cli = load_config(
        path, env=env, overrides={"robot.name": "cli-bot", "state.dir": None, "record.path": "x.mcap"}
    )
    assert cli.robot_name == "cli-bot" and cli.state.dir == "/env/state" and cli.record.path == "x.mcap"
    # LOCI_CONFIG names the file when none is given; an error says where the bad value came from
    assert load_config(env={"LOCI_CONFIG": str(path)}).robot_name == "rosie"
    with pytest.raises(ConfigError, match=r"LOCI_BUS_MODE"):
        load_config(path, env={"LOCI_BUS_MODE": "router"})
    with pytest.raises(ConfigError, match=r"LOCI_ROBOT"):
        load_config(path, env={"LOCI_ROBOT": "a/b"})


def test_the_config_is_frozen() -> None:
    cfg = load_config(table={}, env={})
    with pytest.raises(AttributeError):
        cfg.robot = cfg.robot  # type: ignore[misc]
    assert isinstance(cfg, AgentConfig)


def test_docs_list_every_key_and_environment_variable() -> None:
    doc = (REPO / "docs" / "agent.md").read_text()
    cfg = load_config(table={"laser": {"port": "/dev/null"}}, env={})
    for section in (
        "laser",
        "odometry",
        "places",
        "state",
        "record",
        "diagnostics",
        "local_map",
        "rear_beams",
        "camera",
        "conceptual",
        "objects",
        "follow",
        "foxglove",
        "ros2",
    ):
        value = getattr(cfg, section)
        for name in value.__dataclass_fields__:
            if section == "rear_beams" and name in ("n_beams", "max_range"):
                continue
            described = re.search(rf"`{name}`", doc) or f"`[{section}.{name}]`" in doc
            assert described, f"docs/agent.md does not describe [{section}] {name}"
    for name in [*cfg.navigation.__dataclass_fields__, *cfg.doorways.__dataclass_fields__, "x", "y", "yaw"]:
        assert f"`{name}`" in doc, f"docs/agent.md does not describe {name}"
    for var in ENV_VARS:
        assert var in doc, f"docs/agent.md does not mention {var}"


def test_loci_run_refuses_a_bad_configuration(tmp_path: Path) -> None:
    bad = write(tmp_path, '[laser]\nprot = "/dev/ttyUSB0"\n')
    out = subprocess.run(
        [sys.executable, "-m", "agent.cli", "run", "--config", str(bad)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
        env={"PATH": "/usr/bin:/bin", "HOME": str(tmp_path)},
    )
    assert out.returncode == 2 and "unknown key 'prot'" in out.stderr, out.stderr


def test_every_environment_variable_a_unit_sets_is_one_the_configuration_reads() -> None:
    """The variables come from the configuration's own fields (``env`` metadata), so a systemd
    unit that sets one the code does not read (LOCI_BUS_CONFIG_FILE once) fails here."""
    import re

    units = sorted((REPO / "deploy" / "systemd").glob("*.service"))
    assert units
    for unit in units:
        for var in re.findall(r"^Environment=(LOCI_\w+)=", unit.read_text(), flags=re.M):
            assert var in ENV_VARS, f"{unit.name} sets {var}, which no configuration field reads"
    # and each variable really sets its key
    for var, (section, key, _) in ENV_VARS.items():
        value = "tcp/127.0.0.1:7450" if section == "bus" and key in ("listen", "connect") else "x"
        if (section, key) == ("bus", "mode"):
            value = "peer"  # client mode would need a router's endpoint as well
        if (section, key) == ("laser", "source"):
            value = "bus"
        cfg = load_config(table={"laser": {"port": "/dev/null"}}, env={var: value})
        got = getattr(getattr(cfg, section), key)
        assert got == value or got == (value,) or str(got).endswith(value), (var, got)
