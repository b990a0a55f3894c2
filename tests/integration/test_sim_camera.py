"""The virtual camera, its world and textures, checked with a real SIFT matcher.

The matcher here (SIFT, Lowe's ratio test, one match per image keypoint, RANSAC homography)
is test code only; it stands in for the recogniser that comes later in knowledge/.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Sequence
from functools import cache
from typing import Any

import cv2
import numpy as np
import pytest

from drivers.camera import open_camera
from drivers.messages import Pose2D
from drivers.sim.camera import SimCameraSource
from knowledge.metric.grid import OccupancyGrid
from sim.camera_view import CameraMount, VirtualCamera
from sim.objects import CATALOGUE, WorldObject, object_texture, texture
from sim.world import SimWorld, demo_world

W, H, HFOV = 640, 480, 60.0
FX = (W / 2) / math.tan(math.radians(HFOV) / 2)
CAM_Z = 1.0
#: A match needs this many RANSAC inliers; chance level (measured below) stays far under it.
FOUND = 20

_SIFT = cv2.SIFT.create()
#: SIFT keypoints and their ``(n, 128)`` descriptors.
Features = tuple[Sequence[cv2.KeyPoint], Any]


@cache
def _texture_features(name: str, kind: str, aspect: float) -> Features:
    tex = texture(name, kind=kind, aspect=aspect)
    return _SIFT.detectAndCompute(cv2.cvtColor(np.ascontiguousarray(tex), cv2.COLOR_BGR2GRAY), None)


def features(image: np.ndarray) -> Features:
    return _SIFT.detectAndCompute(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), None)


def match(obj: WorldObject, image: np.ndarray | Features) -> tuple[int, np.ndarray | None]:
    """RANSAC inliers of the object's texture in ``image`` and the homography texture → image."""
    k1, d1 = _texture_features(obj.name, obj.kind, obj.width_m / obj.height_m)
    k2, d2 = features(image) if isinstance(image, np.ndarray) else image
    if d2 is None or len(k2) < 2:
        return 0, None
    best: dict[int, cv2.DMatch] = {}
    for pair in cv2.BFMatcher().knnMatch(d1, d2, k=2):
        if len(pair) == 2 and pair[0].distance < 0.75 * pair[1].distance:
            m = pair[0]
            if m.trainIdx not in best or m.distance < best[m.trainIdx].distance:
                best[m.trainIdx] = m  # one texture point per image point: no lattice pile-ups
    if len(best) < 4:
        return 0, None
    src = np.array([k1[m.queryIdx].pt for m in best.values()], dtype=np.float32)
    dst = np.array([k2[m.trainIdx].pt for m in best.values()], dtype=np.float32)
    Hm, mask = cv2.findHomography(src, dst, cv2.RANSAC, 5.0)
    if Hm is None:
        return 0, None
    return int(mask.sum()), Hm


def _room(occluder: bool = False) -> OccupancyGrid:
    """A 10 m × 10 m room centred on the origin; optionally a wall x ∈ [1.5, 1.6], y ∈ [-1, 1]."""
    occ = np.zeros((200, 200), bool)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = True, True, True, True
    grid = OccupancyGrid.from_masks(occ, 0.05, origin=(-5.0, -5.0, 0.0))
    if occluder:
        rc = grid.world_to_cell(np.array([[1.52, 0.98], [1.58, -0.98]]))
        occ[rc[0, 0] : rc[1, 0] + 1, rc[0, 1] : rc[1, 1] + 1] = True
        grid = OccupancyGrid.from_masks(occ, 0.05, origin=(-5.0, -5.0, 0.0))
    return grid


def _camera(world: SimWorld, **kw: float) -> VirtualCamera:
    opts = {"noise_sigma": 2.0, "blur_sigma": 0.6, **kw}
    return VirtualCamera(world, width=W, height=H, hfov_deg=HFOV, mount=CameraMount(z=CAM_Z), **opts)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def chance_level() -> int:
    """The most inliers any object's texture gets in renders that do not show it."""
    empty = features(_camera(SimWorld(_room())).render(Pose2D(0.0, 0.0, 0.0)))
    worst = 0
    kinds = ["couch", "television", "bookcase", "charging_station", "monitor"]
    for k in kinds:
        worst = max(worst, match(WorldObject.place(k, 2.0, 0.0, math.pi, name=k), empty)[0])
    return worst


@pytest.mark.parametrize("kind", ["television", "couch"])
@pytest.mark.parametrize("dist", [1.0, 2.0, 3.0, 4.0])
def test_object_in_view_is_found_where_the_geometry_says(kind: str, dist: float, chance_level: int) -> None:
    lateral = 0.25
    obj = WorldObject.place(kind, dist, lateral, math.pi, name=f"{kind}_x")
    rendering = _camera(SimWorld(_room(), (obj,))).render_full(Pose2D(0.0, 0.0, 0.0))
    inliers, Hm = match(obj, rendering.image)
    assert inliers >= max(FOUND, 3 * chance_level), f"{kind} at {dist} m: {inliers} inliers"
    assert Hm is not None
    th, tw = object_texture(obj).shape[:2]
    # pixel-centre coordinates (OpenCV's and SIFT's): the image centre is ((W - 1) / 2, (H - 1) / 2)
    centre = cv2.perspectiveTransform(np.array([[[(tw - 1) / 2, (th - 1) / 2]]], dtype=np.float32), Hm)[0, 0]
    zc = obj.elevation_m + obj.height_m / 2
    expected = ((W - 1) / 2 - FX * lateral / dist, (H - 1) / 2 + FX * (CAM_Z - zc) / dist)
    assert centre == pytest.approx(expected, abs=1.5)
    (view,) = rendering.objects
    assert view.name == obj.name and view.centre == pytest.approx(expected, abs=0.5)
    assert view.depth == pytest.approx(dist)


def test_chance_level_is_low(chance_level: int) -> None:
    assert chance_level < FOUND / 2


def test_wall_occludes_an_object() -> None:
    obj = WorldObject.place("television", 3.0, 0.0, math.pi, name="tv")
    visible = _camera(SimWorld(_room(), (obj,))).render_full(Pose2D(0.0, 0.0, 0.0))
    hidden = _camera(SimWorld(_room(occluder=True), (obj,))).render_full(Pose2D(0.0, 0.0, 0.0))
    assert [v.name for v in visible.objects] == ["tv"] and match(obj, visible.image)[0] >= FOUND
    assert hidden.objects == ()
    assert match(obj, hidden.image)[0] < FOUND
    # seen from (0, -2) the wall's end at y = -1 m hides the half of the TV with y > 0
    half = _camera(SimWorld(_room(occluder=True), (obj,))).render_full(
        Pose2D(0.0, -2.0, math.atan2(2.0, 3.0))
    )
    (view,) = half.objects
    assert 0.35 < view.visible_fraction < 0.65


def test_not_found_when_looking_away_or_from_behind() -> None:
    obj = WorldObject.place("couch", 3.0, 0.0, math.pi, name="couch")
    cam = _camera(SimWorld(_room(), (obj,)))
    for yaw in (math.radians(75), math.radians(-75)):  # beyond either edge of the view
        assert cam.render_full(Pose2D(0.0, 0.0, yaw)).objects == ()
    r = cam.render_full(Pose2D(0.0, 0.0, math.pi))  # looking away
    assert r.objects == () and match(obj, r.image)[0] < FOUND
    back = WorldObject.place("couch", 3.0, 0.0, 0.0, name="couch")  # faces away from the camera
    r = _camera(SimWorld(_room(), (back,))).render_full(Pose2D(0.0, 0.0, 0.0))
    assert r.objects == () and match(back, r.image)[0] < FOUND


def test_different_objects_are_not_confused(chance_level: int) -> None:
    objs = [
        WorldObject.place("couch", 2.5, 0.0, math.pi, name="couch_a"),
        WorldObject.place("couch", 2.5, 0.0, math.pi, name="couch_b"),
        WorldObject.place("television", 2.5, 0.0, math.pi, name="tv"),
        WorldObject.place("bookcase", 2.5, 0.0, math.pi, name="books"),
        WorldObject.place("charging_station", 2.5, 0.0, math.pi, name="dock"),
    ]
    for shown in objs:
        img = features(_camera(SimWorld(_room(), (shown,))).render(Pose2D(0.0, 0.0, 0.0)))
        scores = {o.name: match(o, img)[0] for o in objs}
        wrong = max(v for k, v in scores.items() if k != shown.name)
        assert scores[shown.name] >= FOUND and wrong < FOUND, scores
        assert scores[shown.name] >= 3 * max(wrong, chance_level), scores


def test_nearer_objects_are_drawn_over_farther_ones() -> None:
    near = WorldObject.place("television", 2.0, 0.0, math.pi, name="tv")
    far = WorldObject.place("bookcase", 4.0, 0.0, math.pi, name="books")
    both = VirtualCamera(SimWorld(_room(), (far, near))).render_full(Pose2D(0.0, 0.0, 0.0))
    alone = VirtualCamera(SimWorld(_room(), (near,))).render_full(Pose2D(0.0, 0.0, 0.0))
    assert [v.name for v in both.objects] == ["books", "tv"]  # drawn farthest first
    x0, y0, x1, y1 = alone.objects[0].bbox
    # inside the TV's box (two pixels in from its anti-aliased edge) the image is the TV alone
    assert np.array_equal(
        both.image[y0 + 2 : y1 - 2, x0 + 2 : x1 - 2], alone.image[y0 + 2 : y1 - 2, x0 + 2 : x1 - 2]
    )
    assert not np.array_equal(both.image, alone.image)


def test_wall_and_floor_edges_follow_the_pinhole_model() -> None:
    cam = VirtualCamera(SimWorld(_room()), width=W, height=H, hfov_deg=HFOV, mount=CameraMount(z=CAM_Z))
    img = cam.render(Pose2D(0.0, 0.0, 0.0)).astype(int)
    d = 4.9  # the wall's face at x = 4.9 m
    col = img[:, W // 2]
    wall = col[H // 2]
    differs = np.abs(col - wall).sum(axis=1) > 12
    bottom = H // 2 + int(np.argmax(differs[H // 2 :]))
    top = H // 2 - int(np.argmax(differs[: H // 2][::-1]))
    assert bottom == pytest.approx((H - 1) / 2 + FX * CAM_Z / d, abs=1)
    assert top == pytest.approx((H - 1) / 2 - FX * (2.5 - CAM_Z) / d, abs=1)
    # a nearer wall is brighter
    near = cam.render(Pose2D(3.0, 0.0, 0.0))
    assert int(near[H // 2, W // 2].sum()) > int(wall.sum())


def test_panorama_looks_around() -> None:
    obj = WorldObject.place("television", 2.5, 0.0, math.pi, name="tv")
    cam = _camera(SimWorld(_room(), (obj,)))
    views = cam.panorama(Pose2D(0.0, 0.0, 0.3), n=8)
    assert len(views) == 8
    yaws = np.unwrap([v.yaw for v in views])
    assert np.diff(yaws) == pytest.approx(np.full(7, math.pi / 4))
    assert [o.name for o in views[0].objects] == ["tv"] and match(obj, views[0].image)[0] >= FOUND
    for k in (2, 3, 4, 5):  # at least 90° away from the TV
        assert views[k].objects == ()


def test_mount_offset_and_yaw() -> None:
    obj = WorldObject.place("television", 2.0, 0.0, math.pi, name="tv")
    world = SimWorld(_room(), (obj,))
    # robot heading +y; the camera 0.5 m ahead and 0.2 m to its left, looking to its right (+x)
    side = VirtualCamera(world, mount=CameraMount(x=0.5, y=0.2, z=1.0, yaw=-math.pi / 2))
    assert side.camera_pose(Pose2D(0.2, -0.5, math.pi / 2)) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    r = side.render_full(Pose2D(0.2, -0.5, math.pi / 2))
    assert [v.name for v in r.objects] == ["tv"]
    assert r.objects[0].centre[0] == pytest.approx((W - 1) / 2, abs=1e-6)


def test_noise_is_seeded() -> None:
    world = SimWorld(_room())
    a = _camera(world, seed=1).render(Pose2D(0.0, 0.0, 0.0))
    b = _camera(world, seed=1).render(Pose2D(0.0, 0.0, 0.0))
    c = _camera(world, seed=2).render(Pose2D(0.0, 0.0, 0.0))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_textures_are_deterministic_distinct_and_rich() -> None:
    a, b = texture("couch_a", kind="couch"), texture("couch_a", kind="couch")
    assert a is b or np.array_equal(a, b)
    assert not a.flags.writeable
    assert not np.array_equal(texture("couch_b", kind="couch"), a)
    for kind, entry in CATALOGUE.items():
        tex = texture(kind)
        assert tex.dtype == np.uint8 and tex.ndim == 3 and tex.shape[2] == 3
        aspect = entry.width_m / entry.height_m
        assert max(tex.shape[:2]) == 480
        assert min(tex.shape[:2]) == 160 or tex.shape[1] / tex.shape[0] == pytest.approx(aspect, rel=0.01)
        assert len(_SIFT.detect(cv2.cvtColor(np.ascontiguousarray(tex), cv2.COLOR_BGR2GRAY))) >= 200, kind
    with pytest.raises(ValueError, match="aspect"):
        texture("x", aspect=0.0)


def test_world_checks_and_geometry() -> None:
    grid = _room(occluder=True)
    with pytest.raises(ValueError, match="stands in a wall"):
        SimWorld(grid, (WorldObject.place("bucket", 4.97, 0.0, math.pi),))
    with pytest.raises(ValueError, match="unique"):
        SimWorld(
            grid, (WorldObject.place("bucket", 1.0, 0.0, 0.0), WorldObject.place("bucket", 2.0, 2.0, 0.0))
        )
    world = SimWorld(grid)
    ranges = world.raycast(0.0, 0.0, np.array([0.0, math.pi / 2, math.pi, -math.pi / 2]), 20.0)
    assert ranges == pytest.approx([1.5, 4.9, 4.9, 4.9], abs=1e-9)
    assert np.isinf(world.raycast(0.0, 0.0, np.array([math.pi / 2]), 3.0)[0])
    assert not world.line_of_sight(np.array([0.0, 0.0]), np.array([3.0, 0.0]))
    assert world.line_of_sight(np.array([0.0, 2.0]), np.array([3.0, 2.0]))
    assert world.clearance(np.array([0.0, 0.0])) == pytest.approx(1.5, abs=0.05)
    with pytest.raises(KeyError, match="no object"):
        world.object("sofa")


def test_demo_world_shows_its_objects() -> None:
    world = demo_world()
    cam = VirtualCamera(world, width=320, height=240)
    views = cam.panorama(Pose2D(3.0, 4.5, 0.0), n=8)
    seen = {o.name for v in views for o in v.objects}
    assert {"couch", "television", "bookcase"} <= seen
    assert not seen & {"fridge", "desk", "charging_station"}  # behind walls


def test_sim_camera_source_reconnects_after_unplug() -> None:
    world = demo_world()
    pose = [Pose2D(3.0, 4.5, math.pi / 2)]

    async def main() -> None:
        cam = open_camera("sim://?width=160&height=120&rate=100&queue=4", world=world, pose=lambda: pose[0])
        assert isinstance(cam, SimCameraSource)
        async with cam:
            f1 = await cam.recv(timeout=2.0)
            assert f1.image is not None and f1.image.shape == (120, 160, 3)
            pose[0] = Pose2D(3.0, 4.5, -math.pi / 2)
            await cam.recv(timeout=2.0)
            f2 = await cam.recv(timeout=2.0)
            assert f2.image is not None and not np.array_equal(f1.image, f2.image)
            cam.reconnect_delay = 0.01
            cam.unplug()
            t0 = time.monotonic()
            while cam.stats().errors < 2 and time.monotonic() - t0 < 5:
                await asyncio.sleep(0.01)
            assert cam.stats().errors >= 2
            cam.replug()
            while cam.stats().reconnects < 1 and time.monotonic() - t0 < 5:
                await asyncio.sleep(0.01)
            assert cam.stats().reconnects == 1
            seq = (await cam.recv(timeout=2.0)).seq
            assert (await cam.recv(timeout=2.0)).seq > seq

    asyncio.run(asyncio.wait_for(main(), 20))
