"""``loci record`` as a user runs it: a separate process joins the bus and writes an MCAP file."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from agent.bus.bridge import publish_stream
from agent.bus.session import listening_endpoints
from agent.bus.testing import session_pair
from agent.recording.replay import McapMessages

REPO = Path(__file__).resolve().parents[2]


def _record(out: Path, endpoint: str, *extra: str) -> subprocess.Popen[str]:
    """Start ``loci record``; returns once it says it is recording (or has ended)."""
    cmd = [
        sys.executable,
        "-m",
        "agent.cli",
        "record",
        str(out),
        "--robot",
        "rosie",
        "--connect",
        endpoint,
        *extra,
    ]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    first = proc.stderr.readline()
    assert first.startswith("recording loci/rosie/**") or proc.wait(10) != 0, first
    return proc


def _publish_until_exit(proc: subprocess.Popen[str], a: object, stop_after: float | None = None) -> int:
    pub = publish_stream(a, "rosie", "place")  # type: ignore[arg-type]
    t0 = time.monotonic()
    i = 0
    while proc.poll() is None:
        pub.put(
            {"schema": "loci.place/1", "stamp": float(i), "label": "corridor", "probabilities": {}, "node": i}
        )
        i += 1
        time.sleep(0.02)
        if stop_after is not None and time.monotonic() - t0 > stop_after:
            proc.send_signal(signal.SIGTERM)
            stop_after = None
        assert time.monotonic() - t0 < 30, "loci record did not stop"
    return i


def _check(out: Path, published: int) -> int:
    msgs = list(McapMessages(out))
    assert 0 < len(msgs) <= published
    assert {m.topic for m in msgs} == {"loci/rosie/place"}
    nodes = [int(m.data.split(b'"node":')[1].split(b"}")[0]) for m in msgs]
    assert nodes == sorted(nodes) and len(set(nodes)) == len(nodes)  # in order, no duplicates
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(msgs)
    return len(msgs)


@pytest.mark.slow
def test_loci_record_for_a_duration(tmp_path: Path) -> None:
    out = tmp_path / "rec.mcap"
    with session_pair() as (a, _):
        (endpoint,) = listening_endpoints(a)
        proc = _record(out, endpoint, "--duration", "2")
        published = _publish_until_exit(proc, a)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    n = _check(out, published)
    assert f"recorded {n} messages" in err
    # refuses to overwrite without --force
    again = subprocess.run(
        [sys.executable, "-m", "agent.cli", "record", str(out), "--duration", "0.1"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert again.returncode == 2 and "exists" in again.stderr and "--force" in again.stderr, again.stderr


def test_loci_record_stops_cleanly_on_sigterm(tmp_path: Path) -> None:
    out = tmp_path / "term.mcap"
    with session_pair() as (a, _):
        (endpoint,) = listening_endpoints(a)
        proc = _record(out, endpoint)
        published = _publish_until_exit(proc, a, stop_after=1.0)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    _check(out, published)


def test_loci_record_with_nothing_on_the_bus_writes_no_file(tmp_path: Path) -> None:
    out = tmp_path / "empty.mcap"
    with session_pair() as (a, _):
        (endpoint,) = listening_endpoints(a)
        proc = _record(out, endpoint, "--duration", "1")
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 1, err
    assert "nothing was published on loci/rosie/**" in err and "no file written" in err
    assert not out.exists()
