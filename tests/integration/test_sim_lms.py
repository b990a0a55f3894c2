"""The virtual LMS: its world, its bytes on a raw pty, and the ``loci sim lms``/``loci sick`` commands."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import termios
import time
import tty
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from drivers.sick import telegrams as tg
from drivers.sick.codec import Acknowledge, StreamParser, Telegram
from drivers.sick.constants import ACK, NAK, Mode
from drivers.sim.lms import Faults, VirtualLMS
from knowledge.errors import MapError
from knowledge.metric.grid import OccupancyGrid
from sim.lms_world import (
    LEG_RADIUS,
    Leg,
    LmsWorld,
    default_sensor_pose,
    load_world_grid,
    people_in,
    ray_circle_ranges,
    walking_person,
)
from sim.world import load_world

REPO = Path(__file__).resolve().parents[2]


def room(rows: int = 82, cols: int = 122, res: float = 0.05) -> OccupancyGrid:
    occ = np.ones((rows, cols), dtype=bool)
    occ[1:-1, 1:-1] = False
    return OccupancyGrid.from_masks(occ, res, name="room")


# ---------------------------------------------------------------------------- the world
def test_ray_circle_ranges_are_exact() -> None:
    centres = np.array([[3.0, 0.0], [0.0, -2.0]])
    radii = np.array([0.5, 0.1])
    tangent = math.asin(0.5 / 3.0) - 1e-9
    r = ray_circle_ranges((0.0, 0.0), np.array([0.0, -math.pi / 2, math.pi / 2, tangent]), centres, radii)
    assert r[0] == pytest.approx(2.5)
    assert r[1] == pytest.approx(1.9)
    assert r[2] == math.inf
    assert r[3] == pytest.approx(math.sqrt(3.0**2 - 0.5**2), abs=1e-3)  # a ray grazing the circle
    assert ray_circle_ranges((3.0, 0.1), np.array([1.0]), centres, radii)[0] == 0.0  # inside a circle


def test_a_leg_in_front_of_a_wall_shadows_it() -> None:
    grid = room()
    pose = (2.05, 2.05, 0.0)
    world = LmsWorld(grid, pose, [Leg((3.05, 2.05))], noise_std=0.0)
    r = world.ranges(0.0, n_beams=181, fov=math.pi, max_range=20.0)
    assert r[90] == pytest.approx(1.0 - 0.06, abs=1e-5)  # straight ahead: the leg
    assert r[0] == pytest.approx(2.0, abs=1e-4)  # to the right: the wall at y = 0.05
    assert r[180] == pytest.approx(2.0, abs=1e-4)  # to the left: the wall at y = 4.05
    assert r[45] == pytest.approx(2.0 / math.cos(math.pi / 4), abs=1e-4)


@pytest.mark.parametrize("bearing_deg", [30.0, -60.0])
@pytest.mark.parametrize(("n_beams", "fov_deg"), [(361, 180), (360, 360)])
def test_a_leg_shows_in_the_beam_at_its_bearing(n_beams: int, fov_deg: int, bearing_deg: float) -> None:
    grid = room()
    pose = (3.05, 2.05, 0.4)  # the room's centre, walls 2 m and more away
    d = 1.2
    a = pose[2] + math.radians(bearing_deg)
    leg = Leg((pose[0] + d * math.cos(a), pose[1] + d * math.sin(a)))
    fov = math.radians(fov_deg)
    walls = LmsWorld(grid, pose, noise_std=0.0).ranges(0.0, n_beams=n_beams, fov=fov, max_range=20.0)
    r = LmsWorld(grid, pose, [leg], noise_std=0.0).ranges(0.0, n_beams=n_beams, fov=fov, max_range=20.0)
    # a 180° scan runs from -90° to +90° inclusive; a full circle starts at 0° with no beam at 360°
    if fov_deg == 360:
        step, first = 2 * math.pi / n_beams, 0.0
    else:
        step, first = fov / (n_beams - 1), -fov / 2
    i = round(((math.radians(bearing_deg) - first) % (2 * math.pi)) / step)
    assert r[i] == pytest.approx(d - LEG_RADIUS, abs=1e-4)
    shadowed = np.flatnonzero(r < walls - 1e-6)
    off = np.abs(shadowed - i)
    off = np.minimum(off, n_beams - off) if fov_deg == 360 else off
    half_width = math.asin(LEG_RADIUS / d) / step  # beams on either side that graze the leg
    assert shadowed.size >= 3 and np.all(off <= half_width + 1)


def test_noise_only_on_hits_and_ranges_stay_in_bounds() -> None:
    grid = room()
    world = LmsWorld(grid, (2.05, 2.05, 0.0), noise_std=0.05, seed=3)
    far = world.ranges(0.0, n_beams=181, fov=math.pi, max_range=1.5)
    assert np.all(far[60:121] == pytest.approx(1.5))  # nothing within 1.5 m ahead: no noise
    near = world.ranges(0.0, n_beams=181, fov=math.pi, max_range=20.0)
    exact = LmsWorld(grid, (2.05, 2.05, 0.0), noise_std=0.0).ranges(
        0.0, n_beams=181, fov=math.pi, max_range=20.0
    )
    d = near - exact
    assert 0.03 < float(np.std(d)) < 0.07
    assert near.dtype == np.float32 and np.all(near >= 0)


def test_a_pose_can_move_with_time() -> None:
    grid = room()
    world = LmsWorld(grid, lambda t: (1.05 + t, 2.05, 0.0), noise_std=0.0)
    ahead0 = world.ranges(0.0, n_beams=3, fov=math.pi, max_range=20.0)[1]
    ahead1 = world.ranges(1.0, n_beams=3, fov=math.pi, max_range=20.0)[1]
    assert ahead0 - ahead1 == pytest.approx(1.0, abs=1e-4)


def test_walking_legs_stay_near_their_path() -> None:
    a, b = walking_person((0.0, 0.0), (2.0, 0.0), speed=1.0)
    for t in np.linspace(0, 10, 101):
        pa, pb = a.at(t), b.at(t)
        assert -0.2 <= pa[0] <= 2.2 and abs(pa[1]) <= 0.11
        assert math.hypot(pa[0] - pb[0], pa[1] - pb[1]) <= 0.35
    assert a.at(1.0)[0] != pytest.approx(a.at(0.0)[0], abs=0.5)


def test_default_sensor_pose_is_free_with_clearance_near_the_centre() -> None:
    occ = np.zeros((60, 100), dtype=bool)
    occ[:, 48:52] = True  # a wall through the middle
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    grid = OccupancyGrid.from_masks(occ, 0.05)
    x, y, th = default_sensor_pose(grid, clearance=0.3)
    r, c = grid.world_to_cell(np.array([x, y]))
    assert grid.free[r, c] and th == 0.0
    assert min(abs(c - 47.5), abs(c - 52)) * 0.05 >= 0.3 - 0.05
    assert abs(c - 50) < 12 and abs(r - 30) < 3


def test_people_walk_in_free_space() -> None:
    grid = room()
    legs = people_in(grid, (3.0, 2.0), 3, seed=1)
    assert len(legs) == 6
    for leg in legs:
        x, y = leg.at(0.5)
        assert 0.0 < x < 6.2 and 0.0 < y < 4.2


def test_world_specs(tmp_path: Path) -> None:
    grid = room(40, 60)
    yaml_path = grid.save(tmp_path / "room.yaml")
    assert load_world_grid(str(yaml_path)).shape == (40, 60)
    png = tmp_path / "room.png"
    cv2.imwrite(str(png), grid.to_image())
    assert load_world_grid(str(png), 0.05).resolution == 0.05
    with pytest.raises(MapError, match="resolution"):
        load_world_grid(str(png))
    with pytest.raises(MapError, match="no such map file"):
        load_world_grid(str(tmp_path / "missing.yaml"))
    with pytest.raises(MapError, match="comes a seed"):
        load_world_grid("gen:x")
    # one syntax for every simulator command: the tour's world works here too
    assert load_world_grid("demo:0").shape == load_world("demo:0")[0].shape


def test_generated_office_world() -> None:
    grid = load_world_grid("gen:1")
    world = LmsWorld(grid, noise_std=0.0)
    r = world.ranges(0.0, n_beams=361, fov=math.pi, max_range=30.0)
    assert np.all(r > 0.25)  # the default pose has clearance
    assert np.any(r < 30.0)  # and sees walls


# ---------------------------------------------------------------------------- raw bytes on the pty
class RawHost:
    """The host end of the line without the driver: termios speed, bytes in and out."""

    def __init__(self, path: Path, baud: int = 9600) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)
        self.set_baud(baud)
        self.parser = StreamParser("reply")

    def set_baud(self, baud: int) -> None:
        attrs = termios.tcgetattr(self.fd)
        attrs[4] = attrs[5] = getattr(termios, f"B{baud}")
        termios.tcsetattr(self.fd, termios.TCSANOW, attrs)

    def send(self, data: bytes) -> None:
        os.write(self.fd, data)

    def read(self, seconds: float) -> bytes:
        out = b""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                out += os.read(self.fd, 4096)
            except BlockingIOError:
                time.sleep(0.005)
        return out

    def ask(self, t: Telegram, seconds: float = 0.5) -> list[Telegram | Acknowledge]:
        """Send ``t``; the events up to the first telegram that comes back (or all after ``seconds``)."""
        self.send(t.encode())
        events: list[Telegram | Acknowledge] = []
        end = time.monotonic() + seconds
        while time.monotonic() < end and not any(isinstance(e, Telegram) for e in events):
            events += self.parser.feed(self.read(0.01))
        return events

    def close(self) -> None:
        os.close(self.fd)


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[VirtualLMS]:
    with VirtualLMS(LmsWorld(room(), (2.05, 1.55, 0.0), noise_std=0.0), link=tmp_path / "lms") as s:
        yield s


@pytest.fixture
def host(sim: VirtualLMS) -> Iterator[RawHost]:
    h = RawHost(sim.link)
    yield h
    h.close()


def test_link_points_at_a_pty(sim: VirtualLMS) -> None:
    assert sim.link.is_symlink()
    assert str(sim.link.readlink()) == sim.pts
    assert sim.pts is not None and sim.pts.startswith("/dev/pts/")


def test_answers_with_ack_then_reply(sim: VirtualLMS, host: RawHost) -> None:
    events = host.ask(tg.request_status())
    assert events[0] is Acknowledge.ACK
    status = tg.ScannerStatus.decode(events[1])  # type: ignore[arg-type]
    assert (status.angle_deg, status.resolution_cdeg) == (180, 50)
    assert status.operating_mode == Mode.ON_REQUEST
    assert tg.decode_type_reply(host.ask(tg.request_type())[1]) == "LMS200;30106"  # type: ignore[arg-type]
    cfg = tg.ScannerConfig.decode(host.ask(tg.request_config())[1])  # type: ignore[arg-type]
    assert cfg.units == 0
    values = tg.MeasuredValues.decode(host.ask(tg.request_values())[1])  # type: ignore[arg-type]
    assert values.values.size == 361
    assert sim.state().requests == 4


def test_bad_crc_and_unknown_commands_get_nak(sim: VirtualLMS, host: RawHost) -> None:
    raw = bytearray(tg.request_status().encode())
    raw[-1] ^= 0xFF
    host.send(bytes(raw))
    assert host.read(0.2) == bytes([NAK])
    host.send(Telegram(0x00, 0x55).encode())
    assert host.read(0.2) == bytes([NAK])
    assert sim.state().naks_sent == 2


def test_wrong_baud_is_garbage_both_ways(sim: VirtualLMS, host: RawHost) -> None:
    host.set_baud(38400)
    assert host.ask(tg.request_status()) == []  # the scanner did not understand us
    assert sim.state().garbage_received > 0
    host.set_baud(9600)
    assert host.ask(tg.switch_mode(Mode.CONTINUOUS))[1] == tg.mode_reply(0)
    host.set_baud(500000)
    junk = host.read(1.0)  # scans at 9600 (0.76 s each) seen at 500 kbaud: bytes, but no telegram
    assert junk and not any(isinstance(e, Telegram) for e in StreamParser("reply").feed(junk))


def test_baud_change_answers_at_the_old_rate_then_switches(sim: VirtualLMS, host: RawHost) -> None:
    events = host.ask(tg.set_baud(500000))
    assert events == [Acknowledge.ACK, tg.mode_reply(0)]
    assert sim.state().baud == 500000
    host.set_baud(500000)
    assert host.ask(tg.switch_mode(Mode.CONTINUOUS))[1] == tg.mode_reply(0)
    got = [e for e in host.parser.feed(host.read(0.3)) if isinstance(e, Telegram)]
    assert len(got) >= 5 and all(t.command == 0xB0 for t in got)


def test_variant_change_and_its_refusal_while_streaming(sim: VirtualLMS, host: RawHost) -> None:
    reply = tg.VariantReply.decode(host.ask(tg.set_variant(100, 25))[1])  # type: ignore[arg-type]
    assert reply == tg.VariantReply(True, 100, 25)
    host.ask(tg.switch_mode(Mode.CONTINUOUS))
    host.send(tg.set_variant(180, 100).encode())
    replies = [e for e in host.parser.feed(host.read(0.3)) if isinstance(e, Telegram) and e.command == 0xBB]
    assert replies and tg.VariantReply.decode(replies[0]) == tg.VariantReply(False, 100, 25)


def test_installation_mode_needs_the_password(host: RawHost) -> None:
    assert host.ask(tg.switch_mode(Mode.INSTALLATION, b"SICK_LMS"))[1] == tg.mode_reply(0)
    assert host.ask(tg.switch_mode(Mode.INSTALLATION, b"wrong"))[1] == tg.mode_reply(2)


def test_injected_faults_show_on_the_line(sim: VirtualLMS, host: RawHost) -> None:
    sim.set_faults(Faults(bitflip=1.0))
    host.send(tg.request_status().encode())
    parser = StreamParser("reply")
    events = parser.feed(host.read(0.3))
    assert Acknowledge.ACK in events and parser.stats.crc_errors == 1
    sim.set_faults(Faults(mute=True))
    host.send(tg.request_status().encode())
    assert host.read(0.2) == b""
    sim.set_faults(Faults())
    sim.send_raw(bytes([ACK, 0x02, 0x99]))
    assert host.read(0.2) == bytes([ACK, 0x02, 0x99])


def test_unplug_removes_the_link_and_replug_brings_a_new_pty(sim: VirtualLMS, host: RawHost) -> None:
    old = sim.pts
    sim.unplug()
    assert not sim.link.exists() and not sim.state().plugged
    try:  # the host's end is dead: end of file (or EIO), never "no data yet"
        assert os.read(host.fd, 10) == b""
    except OSError as exc:
        assert not isinstance(exc, BlockingIOError)
    sim.replug()
    assert sim.link.is_symlink() and str(sim.link.readlink()) == sim.pts
    assert old is not None and sim.pts is not None
    h2 = RawHost(sim.link)
    try:
        assert h2.ask(tg.request_status())[0] is Acknowledge.ACK
    finally:
        h2.close()


def test_refuses_to_replace_a_regular_file(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(ValueError, match="not a symlink"):
        VirtualLMS(LmsWorld(room(), (1.0, 1.0, 0.0)), link=f)


def test_stop_removes_its_temporary_directory() -> None:
    s = VirtualLMS(LmsWorld(room(), (1.0, 1.0, 0.0)))
    link = s.start()
    assert link.is_symlink()
    s.stop()
    assert not link.exists() and not link.parent.exists()


# ---------------------------------------------------------------------------- the commands
def _loci(*args: str) -> list[str]:
    return [sys.executable, "-m", "agent.cli", *args]


@pytest.fixture
def sim_process(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Path]]:
    png = tmp_path / "room.png"
    cv2.imwrite(str(png), room().to_image())
    link = tmp_path / "lms"
    proc = subprocess.Popen(
        _loci(
            "-q",
            "sim",
            "lms",
            "--world",
            str(png),
            "--resolution",
            "0.05",
            "--link",
            str(link),
            "--noise",
            "0",
        ),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    first = proc.stdout.readline().strip()
    try:
        assert first == str(link), proc.stderr.read() if proc.stderr else ""
        yield proc, link
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


#: Scans per second of the virtual LMS at 180°/0.5° (two mirror turns at 75 Hz per scan).
LMS_RATE = 37.5


def _sick_scan(link: Path, *args: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Run ``loci sick scan LINK ARGS --json-lines``: its summaries and its final counters."""
    out = subprocess.run(
        _loci("-q", "sick", "scan", str(link), *args, "--json-lines"),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in out.stdout.splitlines()]
    assert lines and lines[-1]["schema"] == "loci.sick.counters/1", out.stdout
    return [x for x in lines if x["schema"] == "loci.sick.summary/1"], lines[-1]


def _check_scanning(summaries: list[dict[str, Any]], final: dict[str, Any], duration: float) -> None:
    """Every summary window saw room-sized scans, and the rate is the scanner's once it streams."""
    assert final["duration"] >= duration
    assert sum(s["scans"] for s in summaries) == final["scans"]
    # a loaded machine may starve the virtual scanner for a while, never for a third of the time
    assert LMS_RATE / 3 <= final["scans_per_s"] <= 1.2 * LMS_RATE
    assert final["counters"]["crc_errors"] == 0
    assert final["info"]["baud"] == 500000 and final["info"]["n_beams"] == 361
    for s in summaries:
        assert s["scans"] >= 1 and s["n_beams"] == 361 and s["invalid_per_scan"] == 0
        assert 0.2 < s["min"] < s["mean"] < s["max"] < 7.3  # inside a 6 m x 4 m room


@pytest.mark.slow
def test_sim_and_sick_scan_commands_talk_over_the_pty(
    sim_process: tuple[subprocess.Popen[str], Path],
) -> None:
    proc, link = sim_process
    summaries, final = _sick_scan(link, "--duration", "2")
    assert len(summaries) == 2
    _check_scanning(summaries, final, 2.0)

    # --json: the counters alone, as one JSON object (indented, so not one line)
    one = subprocess.run(
        _loci("-q", "sick", "scan", str(link), "--duration", "1", "--json"),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert one.returncode == 0, one.stderr
    counters = json.loads(one.stdout)
    assert counters["schema"] == "loci.sick.counters/1" and counters["scans"] >= 1

    probe = subprocess.run(
        _loci("-q", "sick", "probe", str(link), "--json"),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert probe.returncode == 0, probe.stderr
    info = json.loads(probe.stdout)
    assert info["type_string"] == "LMS200;30106" and info["baud_found"] == 9600

    proc.send_signal(signal.SIGINT)
    assert proc.wait(10) == 0
    assert not link.exists()


@pytest.mark.slow
def test_sick_scan_counts_scanning_time_not_start_up(tmp_path: Path) -> None:
    # left at 38400 baud by an earlier session: the driver waits in vain for an answer at
    # 9600 and at 500000 baud (two 0.5 s attempts each), so starting takes longer than the
    # whole --duration
    world = LmsWorld(room(), (2.05, 1.55, 0.0), noise_std=0.0)
    with VirtualLMS(world, link=tmp_path / "lms", initial_baud=38400) as sim:
        summaries, final = _sick_scan(sim.link, "--duration", "1", "--interval", "0.5")
    assert final["info"]["baud_found"] == 38400
    assert final["startup"] > 2.0 and final["counters"]["timeouts"] >= 4
    assert len(summaries) == 2
    _check_scanning(summaries, final, 1.0)


def test_sick_probe_reports_a_missing_port(tmp_path: Path) -> None:
    out = subprocess.run(
        _loci("sick", "probe", str(tmp_path / "nothing")),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert out.returncode == 2
    assert "cannot open serial port" in out.stderr
