"""The shared option types: bad values are usage errors that say what was expected."""

from __future__ import annotations

import argparse

import pytest

from agent.commands.options import fraction, integer, number, positive_seconds, seconds


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf", "abc", ""])
def test_positive_seconds_refuses(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="positive number of seconds"):
        positive_seconds(text)


def test_seconds_takes_zero_and_refuses_negative() -> None:
    assert seconds("0") == 0.0
    assert positive_seconds("2.5") == 2.5
    with pytest.raises(argparse.ArgumentTypeError, match=">= 0"):
        seconds("-0.1")


def test_number_with_a_minimum_and_integer_with_a_reason() -> None:
    assert number(minimum=1.0)("1.5") == 1.5
    with pytest.raises(argparse.ArgumentTypeError, match="> 1"):
        number(minimum=1.0)("1")
    assert integer(minimum=4)("4") == 4
    with pytest.raises(argparse.ArgumentTypeError, match="a homography needs 4 points"):
        integer(minimum=4, why="a homography needs 4 points")("3")
    with pytest.raises(argparse.ArgumentTypeError, match="integer >= 1"):
        integer()("1.5")


@pytest.mark.parametrize(("text", "ok"), [("0.5", True), ("0", False), ("1", False), ("x", False)])
def test_fraction(text: str, ok: bool) -> None:
    if ok:
        assert fraction(text) == float(text)
    else:
        with pytest.raises(argparse.ArgumentTypeError, match=r"\(0, 1\)"):
            fraction(text)


def test_version_and_log_options_after_the_command() -> None:
    import subprocess
    import sys

    from agent.cli import build_parser

    out = subprocess.run(
        [sys.executable, "-m", "agent.cli", "--version"], capture_output=True, text=True, check=False
    )
    assert out.returncode == 0 and out.stdout.startswith("loci ")
    parser = build_parser()
    # -v and -q after a command (and after a sub-command) as before it
    assert parser.parse_args(["replay", "run.mcap", "-v"]).verbose == 1
    assert parser.parse_args(["-v", "replay", "run.mcap"]).verbose == 1
    assert parser.parse_args(["replay", "run.mcap"]).verbose == 0
    assert parser.parse_args(["evaluate", "log", "r.mcap", "--labels", "l.npz", "-vv"]).verbose == 2
    assert parser.parse_args(["replay", "run.mcap", "-q"]).quiet is True
    assert parser.parse_args(["-q", "replay", "run.mcap"]).quiet is True
