"""Camera sources with real OpenCV on real video files: order, drops, reconnection, JPEG."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Coroutine
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from drivers.camera import (
    CameraSource,
    OpenCVCamera,
    compress_frame,
    decode_jpeg,
    decompress_frame,
    encode_jpeg,
    open_camera,
    parse_camera_url,
)
from drivers.messages import CameraFrame
from knowledge.errors import ConfigError, DeviceError, DeviceTimeout, ProtocolError

W, H = 160, 120


def _write_video(path: Path, n: int, fps: float = 25.0) -> Path:
    """An MJPG AVI whose frame i shows grey level 10·i in its top-left block."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (W, H))
    assert writer.isOpened()
    for i in range(n):
        img = np.full((H, W, 3), 128, np.uint8)
        img[:40, :40] = 10 * i
        cv2.putText(img, str(i), (60, 80), cv2.FONT_HERSHEY_SIMPLEX, 1.5, (0, 0, 255), 3)
        writer.write(img)
    writer.release()
    return path


def _index(frame: CameraFrame) -> int:
    assert frame.image is not None
    return round(float(frame.image[8:32, 8:32].mean()) / 10)


def _run(coro: Coroutine[Any, Any, None]) -> None:
    asyncio.run(asyncio.wait_for(coro, 20))


async def _until(cond: Any, timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.005)


@pytest.fixture
def video(tmp_path: Path) -> Path:
    return _write_video(tmp_path / "clip.avi", 20)


def test_reads_a_video_file_in_order(video: Path) -> None:
    async def main() -> None:
        async with OpenCVCamera(video, realtime=False, queue_size=32, frame_id="cam0") as cam:
            frames = [f async for f in cam]
        assert [_index(f) for f in frames] == list(range(20))
        assert [f.seq for f in frames] == list(range(20))
        assert all(f.frame_id == "cam0" and f.image is not None for f in frames)
        assert frames[0].image.shape == (H, W, 3)  # type: ignore[union-attr]
        stamps = [f.stamp for f in frames]
        assert stamps == sorted(stamps) and abs(stamps[0] - time.time()) < 10
        s = cam.stats()
        assert (s.frames, s.drops, s.reconnects, s.errors) == (20, 0, 0, 0)
        with pytest.raises(DeviceError, match="ended"):
            await cam.recv(timeout=0.5)

    _run(main())


def test_a_file_plays_at_its_frame_rate_in_realtime_mode(tmp_path: Path) -> None:
    path = _write_video(tmp_path / "slow.avi", 6, fps=25.0)

    async def main() -> None:
        t0 = time.monotonic()
        async with OpenCVCamera(path, queue_size=16) as cam:
            frames = [f async for f in cam]
        assert len(frames) == 6
        assert time.monotonic() - t0 >= 5 / 25.0 * 0.9  # five frame periods at least

    _run(main())


def test_full_queue_drops_the_oldest(video: Path) -> None:
    async def main() -> None:
        cam = OpenCVCamera(video, realtime=False, queue_size=3)
        await cam.start()
        await _until(lambda: cam.ended)  # nobody reads while the whole file is captured
        s = cam.stats()
        assert (s.frames, s.drops) == (20, 17)
        rest = [f async for f in cam]
        assert [_index(f) for f in rest] == [17, 18, 19]
        assert [f.seq for f in rest] == [17, 18, 19]
        await cam.close()

    _run(main())


def test_slow_consumer_sees_the_newest_frames(video: Path) -> None:
    async def main() -> None:
        got = []
        async with OpenCVCamera(video, rate_hz=200.0, queue_size=2) as cam:
            async for f in cam:
                got.append(f.seq)
                await asyncio.sleep(0.03)  # six frame periods per frame read
        s = cam.stats()
        assert got == sorted(got) and len(set(got)) == len(got)
        assert s.drops > 0 and len(got) + s.drops == s.frames == 20
        assert got[-1] == 19  # the newest frame always gets through

    _run(main())


def test_missing_file_and_device_give_clear_errors(tmp_path: Path) -> None:
    async def main() -> None:
        with pytest.raises(DeviceError, match="does not exist"):
            await OpenCVCamera(tmp_path / "nope.avi").start()
        bad = tmp_path / "bad.avi"
        bad.write_bytes(b"this is not a video")
        with pytest.raises(DeviceError, match="cannot open camera"):
            await OpenCVCamera(bad).start()
        with pytest.raises(DeviceError, match=r"cannot open camera 99 \(device\)"):
            await open_camera("99").start()

    _run(main())
    assert not [t for t in threading.enumerate() if t.name.startswith("camera ")]


class _CrashingBackend(CameraSource):
    """A backend whose open crashes inside OpenCV (an empty image handed to ``cv2.resize``)."""

    def _open(self) -> None:
        cv2.resize(np.zeros((0, 0, 3), np.uint8), (W, H))

    def _read(self) -> np.ndarray | None:
        raise AssertionError("never opened, never read")

    def _close(self) -> None:
        pass


def test_a_backend_crash_at_open_fails_start_at_once_with_its_cause() -> None:
    async def main() -> None:
        cam = _CrashingBackend("crasher", open_timeout=3.0)
        with pytest.raises(DeviceError, match=r"camera crasher could not be opened: .*error") as err:
            await cam.start()
        assert not isinstance(err.value, DeviceTimeout)
        assert isinstance(err.value.__cause__, cv2.error)
        assert cam.ended
        with pytest.raises(DeviceError, match="ended"):
            await cam.recv(timeout=0.5)

    _run(main())
    assert not [t for t in threading.enumerate() if t.name == "camera crasher"]


def test_recv_times_out(video: Path) -> None:
    async def main() -> None:
        async with OpenCVCamera(video, rate_hz=0.5) as cam:
            await cam.recv(timeout=2.0)
            with pytest.raises(DeviceTimeout, match=r"within 0\.05 s"):
                await cam.recv(timeout=0.05)

    _run(main())


def test_looping_file_reconnects_at_its_end(tmp_path: Path) -> None:
    path = _write_video(tmp_path / "five.avi", 5)

    async def main() -> None:
        cam = open_camera(f"file://{path}?loop=1&realtime=0&rate=200&queue=100")
        async with cam:
            frames = [await cam.recv(timeout=2.0) for _ in range(12)]
        assert [_index(f) for f in frames] == [i % 5 for i in range(12)]
        assert [f.seq for f in frames] == list(range(12))
        assert cam.stats().reconnects >= 2 and cam.stats().errors == 0

    _run(main())


def test_unplugged_file_is_reopened_when_it_comes_back(tmp_path: Path) -> None:
    path = _write_video(tmp_path / "five.avi", 5)
    away = tmp_path / "away.avi"

    async def main() -> None:
        cam = OpenCVCamera(
            path, loop=True, rate_hz=200.0, queue_size=4, reconnect_delay=0.01, max_reconnect_delay=0.05
        )
        async with cam:
            await cam.recv(timeout=2.0)
            path.rename(away)
            await _until(lambda: cam.stats().errors >= 2)
            assert "does not exist" in (cam.stats().last_error or "")
            before = cam.stats().reconnects
            away.rename(path)
            await _until(lambda: cam.stats().reconnects > before)
            seq = (await cam.recv(timeout=2.0)).seq
            assert (await cam.recv(timeout=2.0)).seq > seq

    _run(main())


def test_gives_up_after_max_reconnects(tmp_path: Path) -> None:
    path = _write_video(tmp_path / "five.avi", 5)

    async def main() -> None:
        cam = OpenCVCamera(
            path, loop=True, realtime=False, queue_size=50, reconnect_delay=0.01, max_reconnects=2
        )
        await cam.start()
        path.unlink()
        await _until(lambda: cam.ended)
        with pytest.raises(DeviceError, match="gave up after 2 failed reconnects"):
            async for _ in cam:
                pass
        assert cam.stats().errors == 2
        await cam.close()

    _run(main())


def test_close_joins_the_thread_and_is_idempotent(video: Path) -> None:
    async def main() -> None:
        cam: CameraSource = OpenCVCamera(video, loop=True, rate_hz=100.0)
        await cam.start()
        await cam.recv(timeout=2.0)
        await cam.close()
        await cam.close()
        assert not [t for t in threading.enumerate() if t.name == f"camera {video}"]
        with pytest.raises(RuntimeError, match="already started"):
            await cam.start()

    _run(main())


def test_camera_urls() -> None:
    assert parse_camera_url("0").kind == "device" and parse_camera_url("0").target == 0
    spec = parse_camera_url("2?width=640&height=480&fps=30")
    assert spec.options == {"width": 640, "height": 480, "fps": 30.0}
    assert parse_camera_url("/dev/video1").target == "/dev/video1"
    spec = parse_camera_url("file:///data/run%201.avi?loop=1&realtime=0&queue=8")
    assert (spec.kind, spec.target) == ("file", "/data/run 1.avi")
    assert spec.options == {"loop": True, "realtime": False, "queue_size": 8}
    assert parse_camera_url("clips/a.mp4").kind == "file"
    url = "rtsp://cam.local:554/stream?channel=1"
    assert (parse_camera_url(url).kind, parse_camera_url(url).target) == ("stream", url)
    assert parse_camera_url("sim://?fov=90&rate=5").options == {"hfov_deg": 90.0, "rate_hz": 5.0}
    with pytest.raises(ConfigError, match="unknown file camera option 'lopo'"):
        parse_camera_url("file:///a.avi?lopo=1")
    with pytest.raises(ConfigError, match="option 'loop'"):
        parse_camera_url("file:///a.avi?loop=maybe")
    with pytest.raises(ConfigError, match="unknown camera scheme 'gopher"):
        parse_camera_url("gopher://x")
    with pytest.raises(ValueError, match="queue_size"):
        open_camera("file:///a.avi?queue=0")


def test_jpeg_round_trip() -> None:
    yy, xx = np.mgrid[0:120, 0:160]
    img = np.stack([xx * 1.5, yy * 2.0, (xx + yy) * 0.9], axis=-1).astype(np.uint8)
    cv2.circle(img, (80, 60), 30, (0, 0, 255), -1)
    hi, lo = encode_jpeg(img, 95), encode_jpeg(img, 10)
    assert hi[:2] == b"\xff\xd8" and len(lo) < len(hi)
    back = decode_jpeg(hi)
    assert back.shape == img.shape and back.dtype == np.uint8

    def psnr(a: np.ndarray) -> float:
        return float(10 * np.log10(255**2 / np.mean((a.astype(float) - img.astype(float)) ** 2)))

    assert psnr(back) > 30.0 and psnr(back) > psnr(decode_jpeg(lo)) + 5.0
    frame = CameraFrame(stamp=12.5, seq=7, frame_id="cam", image=img)
    packed = compress_frame(frame, quality=90)
    assert packed.image is None and packed.jpeg is not None
    assert (packed.stamp, packed.seq, packed.frame_id) == (12.5, 7, "cam")
    unpacked = decompress_frame(packed)
    assert unpacked.image is not None and unpacked.image.shape == img.shape
    assert compress_frame(frame, keep_image=True).image is not None
    with pytest.raises(ValueError, match="quality"):
        encode_jpeg(img, 0)
    with pytest.raises(ProtocolError, match="not a decodable JPEG"):
        decode_jpeg(b"\x00\x01garbage")
