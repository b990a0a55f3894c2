"""``loci dialogue --config ROBOT.toml``: the robot's name and bus from the agent's own file."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.commands.dialogue import register


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="loci")
    register(parser.add_subparsers())
    return parser.parse_args(["dialogue", *argv])


def _config(args: argparse.Namespace) -> object:
    from agent.commands.dialogue import config_from_args

    return config_from_args(args)


def test_peer_mode_connects_to_the_agents_listen_endpoint(tmp_path: Path) -> None:
    toml = tmp_path / "robot.toml"
    toml.write_text('[robot]\nname = "rosie"\n[bus]\nlisten = ["tcp/127.0.0.1:7555"]\n', encoding="utf-8")
    config = _config(_parse(["--config", str(toml), "--no-speech"]))
    assert config.robot == "rosie"  # type: ignore[attr-defined]
    assert config.bus.connect == ("tcp/127.0.0.1:7555",)  # type: ignore[attr-defined]
    assert config.bus.listen == ("tcp/127.0.0.1:0",)  # type: ignore[attr-defined]


def test_client_mode_keeps_the_router_and_options_override(tmp_path: Path) -> None:
    toml = tmp_path / "robot.toml"
    toml.write_text(
        '[robot]\nname = "rosie"\n[bus]\nmode = "client"\nlisten = []\nconnect = ["tcp/10.0.0.1:7447"]\n',
        encoding="utf-8",
    )
    config = _config(_parse(["--config", str(toml), "--robot", "other"]))
    assert config.bus.mode == "client"  # type: ignore[attr-defined]
    assert config.bus.connect == ("tcp/10.0.0.1:7447",)  # type: ignore[attr-defined]
    assert config.robot == "other"  # type: ignore[attr-defined]
