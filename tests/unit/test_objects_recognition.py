"""Object recognition on frames rendered by the virtual camera (real SIFT, real FLANN, real RANSAC).

The database is taught the sim objects' pictures (sim/objects.py), exactly what the
demo does; the frames are rendered from poses with the pictures at known places, so every
expected answer comes from the scene's geometry, not from the recogniser.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers.messages import Pose2D
from knowledge.metric.grid import OccupancyGrid
from knowledge.objects import Detection, ObjectDatabase, ObjectRecogniser, RecognitionParams, extract_features
from knowledge.objects.recognition import plausible_outline
from sim.camera_view import CameraMount, VirtualCamera
from sim.objects import WorldObject, object_texture, texture
from sim.world import SimWorld

W, H, HFOV = 640, 480, 60.0
#: Taught: name → sim kind. Two couches: same drawer, same palette, different seeds.
TAUGHT = {
    "couch": "couch",
    "red couch": "couch",
    "television": "television",
    "bookcase": "bookcase",
    "charging station": "charging_station",
    "fridge": "fridge",
    "monitor": "monitor",
}
CAM = Pose2D(-4.0, 0.0, 0.0)


def _room() -> OccupancyGrid:
    """A 10 m × 10 m empty room centred on the origin."""
    occ = np.zeros((200, 200), bool)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = True, True, True, True
    return OccupancyGrid.from_masks(occ, 0.05, origin=(-5.0, -5.0, 0.0))


ROOM = _room()


def _place(name: str, dist: float, lateral: float = 0.0, turn_deg: float = 0.0) -> WorldObject:
    """The taught object ``name`` ``dist`` metres ahead of CAM, ``lateral`` metres to its left,
    turned by ``turn_deg`` from facing the camera squarely."""
    kind = TAUGHT.get(name, name)
    return WorldObject.place(
        kind, CAM.x + dist, CAM.y + lateral, math.pi + math.radians(turn_deg), name=name.replace(" ", "_")
    )


def _camera(*objs: WorldObject, noise: float = 2.0) -> VirtualCamera:
    return VirtualCamera(
        SimWorld(ROOM, objs),
        width=W,
        height=H,
        hfov_deg=HFOV,
        mount=CameraMount(z=1.2),
        noise_sigma=noise,
        blur_sigma=0.6,
        seed=7,
    )


@pytest.fixture(scope="module")
def database(tmp_path_factory: pytest.TempPathFactory) -> ObjectDatabase:
    db = ObjectDatabase.open(tmp_path_factory.mktemp("objects") / "db")
    for name in TAUGHT:
        # "red couch" is an instance of Couch; the others' kinds come from their names
        db.add(name, [object_texture(_place(name, 2.0))], kind="Couch" if name == "red couch" else None)
    return db


@pytest.fixture(scope="module")
def recogniser(database: ObjectDatabase) -> ObjectRecogniser:
    return ObjectRecogniser(ObjectDatabase.open(database.folder))


def _names(dets: list[Detection]) -> list[str]:
    return [d.name for d in dets]


@pytest.mark.parametrize(
    ("name", "dist", "turn"),
    [
        ("television", 1.5, 0.0),
        ("television", 3.0, 30.0),
        ("television", 4.0, 0.0),
        ("couch", 2.0, -30.0),
        ("couch", 4.5, 0.0),
        ("bookcase", 3.0, 20.0),
        ("fridge", 3.5, -20.0),
        ("monitor", 2.5, 0.0),
    ],
)
def test_object_is_recognised_where_the_camera_sees_it(
    recogniser: ObjectRecogniser, name: str, dist: float, turn: float
) -> None:
    obj = _place(name, dist, lateral=0.3, turn_deg=turn)
    cam = _camera(obj)
    rendering = cam.render_full(CAM)
    (view,) = rendering.objects
    dets = recogniser.recognise(rendering.image, intrinsics=cam.intrinsics)
    assert _names(dets) == [name], [(d.name, d.inliers) for d in dets]
    (d,) = dets
    assert d.kind == "".join(w.capitalize() for w in name.split())
    assert d.inliers >= 12 and 0 < d.score < 1 and d.matches >= d.inliers
    # the picture's centre where the camera put it (ground truth from the renderer)
    assert d.centre == pytest.approx(view.centre, abs=3.0)
    # the outline's corners where the pinhole model puts the object's world corners
    expected = _project_corners(cam, obj)
    err = np.abs(d.corners - expected).max()
    assert err < 0.03 * np.ptp(expected[:, 0]) + 2.0, (err, np.ptp(expected[:, 0]))
    # an object 0.3 m to the left is seen left of the optical axis (positive bearing)
    assert d.bearing == pytest.approx(math.atan2(0.3, dist), abs=0.02)


def _project_corners(cam: VirtualCamera, obj: WorldObject) -> np.ndarray:
    """``(4, 2)`` pixels of the object's world corners seen from CAM (level pinhole camera)."""
    c = obj.corners()
    rel = c[:, :2] - np.array([CAM.x, CAM.y])
    depth = rel[:, 0]  # CAM looks along +x
    u = cam.cx - cam.fx * rel[:, 1] / depth
    v = cam.cy + cam.fy * (cam.mount.z - c[:, 2]) / depth
    return np.stack([u, v], axis=1)


def test_empty_room_and_untaught_objects_give_no_detection(recogniser: ObjectRecogniser) -> None:
    assert recogniser.recognise(_camera().render(CAM)) == []
    # pictures the database never saw: other kinds, and a couch with another seed
    strangers = (
        _place("desk", 2.5, lateral=0.8),
        _place("whiteboard", 3.5, lateral=-1.2),
        WorldObject.place("couch", CAM.x + 4.0, 1.8, math.pi, name="stranger_couch"),
    )
    frame = _camera(*strangers).render_full(CAM)
    assert len(frame.objects) == 3
    assert recogniser.recognise(frame.image) == []


def test_two_objects_in_one_frame_are_both_found(recogniser: ObjectRecogniser) -> None:
    tv = _place("television", 3.0, lateral=0.7)
    station = _place("charging station", 2.0, lateral=-0.5)
    cam = _camera(tv, station)
    rendering = cam.render_full(CAM)
    dets = recogniser.recognise(rendering.image)
    assert sorted(_names(dets)) == ["charging station", "television"]
    assert [d.score for d in dets] == sorted((d.score for d in dets), reverse=True)
    by_name = {d.name: d for d in dets}
    truth = {v.name: v for v in rendering.objects}
    assert by_name["television"].centre == pytest.approx(truth["television"].centre, abs=3.0)
    assert by_name["charging station"].centre == pytest.approx(truth["charging_station"].centre, abs=3.0)
    assert by_name["television"].centre[0] < by_name["charging station"].centre[0]  # left of it


def test_similar_objects_are_not_confused(recogniser: ObjectRecogniser) -> None:
    for name in ("couch", "red couch"):
        dets = recogniser.recognise(_camera(_place(name, 3.0)).render(CAM))
        assert _names(dets) == [name]
        assert dets[0].kind == "Couch"


def test_object_out_of_view_is_not_reported(recogniser: ObjectRecogniser) -> None:
    tv = _place("television", 3.0)
    cam = _camera(tv)
    away = cam.render_full(Pose2D(CAM.x, CAM.y, math.radians(90)))
    assert away.objects == ()
    assert recogniser.recognise(away.image) == []


def test_several_pictures_per_object(tmp_path: Path) -> None:
    """A second picture (the object seen from the side) is matched when it fits better."""
    tv = _place("television", 3.0, turn_deg=55.0)
    cam = _camera(tv)
    frame = cam.render(CAM)
    db = ObjectDatabase.open(tmp_path / "db")
    db.add("television", [texture("television", kind="television", aspect=tv.width_m / tv.height_m)])
    db.add("couch", [object_texture(_place("couch", 2.0))])
    # a side view: the same scene rendered turned 45°, cropped to the picture
    side = _camera(_place("television", 1.6, turn_deg=45.0)).render_full(CAM)
    x0, y0, x1, y1 = side.objects[0].bbox
    db.add("television", [side.image[y0:y1, x0:x1]])
    assert db.entry("television").image_sizes[1] == (x1 - x0, y1 - y0)
    dets = ObjectRecogniser(db).recognise(frame)
    assert _names(dets) == ["television"]
    assert dets[0].image_index == 1


def test_tighter_thresholds_find_less(recogniser: ObjectRecogniser, database: ObjectDatabase) -> None:
    frame = _camera(_place("television", 4.0)).render(CAM)
    (d,) = recogniser.recognise(frame)
    # FLANN's trees and RANSAC's samples are random: a margin around the inlier count
    strict = ObjectRecogniser(database.views(), RecognitionParams(min_inliers=2 * d.inliers))
    assert strict.recognise(frame) == []
    lenient = ObjectRecogniser(database.views(), RecognitionParams(min_inliers=d.inliers // 2))
    assert _names(lenient.recognise(frame)) == ["television"]


def test_features_of_a_large_image_are_in_its_own_pixels() -> None:
    tex = np.ascontiguousarray(texture("television"))
    big = cv2.resize(tex, (tex.shape[1] * 3, tex.shape[0] * 3), interpolation=cv2.INTER_CUBIC)
    f = extract_features(big)
    assert f.image_size == (big.shape[1], big.shape[0])
    assert f.points[:, 0].max() > 1024  # shrunk to 1024 for SIFT, mapped back
    assert (
        f.points.min() >= -0.5 and f.points[:, 0].max() < big.shape[1] and f.points[:, 1].max() < big.shape[0]
    )
    with pytest.raises(ValueError, match="uint8"):
        extract_features(big.astype(np.float32))
    with pytest.raises(ValueError, match="too small"):
        extract_features(np.zeros((8, 8), np.uint8))


def test_plausibility_rejects_impossible_outlines() -> None:
    p = RecognitionParams()
    outline = np.array([[-0.5, -0.5], [99.5, -0.5], [99.5, 49.5], [-0.5, 49.5]])
    shift = np.array([[1.0, 0, 200], [0, 1.0, 100], [0, 0, 1]])
    assert plausible_outline(shift, outline, (640, 480), p) is not None
    mirror = np.array([[-1.0, 0, 300], [0, 1.0, 100], [0, 0, 1]])
    assert plausible_outline(mirror, outline, (640, 480), p) is None
    tiny = np.array([[0.05, 0, 200], [0, 0.05, 100], [0, 0, 1]])
    assert plausible_outline(tiny, outline, (640, 480), p) is None
    huge = np.array([[30.0, 0, 0], [0, 30.0, 0], [0, 0, 1]])
    assert plausible_outline(huge, outline, (640, 480), p) is None
    behind = np.array([[1.0, 0, 0], [0, 1.0, 0], [-0.02, 0, 1]])  # x = 50 maps to infinity
    assert plausible_outline(behind, outline, (640, 480), p) is None
    squeezed = np.array([[4.0, 0, 0], [0, 4.0, 0], [0.09, 0, 1]])  # right edge 10x shorter than the left
    assert plausible_outline(squeezed, outline, (640, 480), p) is None
    assert plausible_outline(np.full((3, 3), np.nan), outline, (640, 480), p) is None


def test_recogniser_without_objects_finds_nothing() -> None:
    frame = _camera(_place("television", 2.0)).render(CAM)
    assert ObjectRecogniser([]).recognise(frame) == []
    with pytest.raises(ValueError, match="image or its features"):
        ObjectRecogniser([]).recognise()
