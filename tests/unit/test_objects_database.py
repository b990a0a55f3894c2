"""The object database folder: round trip, names and kinds, atomic writes, damaged files."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from knowledge.errors import ModelError
from knowledge.objects import ObjectDatabase, class_name
from knowledge.objects.database import FORMAT, INDEX, file_name
from sim.objects import texture


def tex(kind: str, name: str | None = None) -> np.ndarray:
    return np.ascontiguousarray(texture(name or kind, kind=kind))


@pytest.fixture
def db(tmp_path: Path) -> ObjectDatabase:
    d = ObjectDatabase.open(tmp_path / "objects")
    d.add("television", [tex("television")])
    d.add("charging station", [tex("charging_station"), tex("charging_station", "dock2")])
    return d


def test_round_trip_keeps_every_keypoint_and_descriptor(db: ObjectDatabase) -> None:
    again = ObjectDatabase.open(db.folder)
    assert again.names() == ["charging station", "television"]
    e = again.entry("Charging  Station")  # case and spacing do not matter
    assert e.kind == "ChargingStation" and len(e.image_sizes) == 2
    img = tex("charging_station")
    assert e.image_sizes[0] == (img.shape[1], img.shape[0])
    from knowledge.objects import extract_features

    fresh = extract_features(img)
    (v0, v1) = again.views(["charging station"])
    assert (v0.image_index, v1.image_index) == (0, 1)
    assert v0.name == "charging station" and v0.kind == "ChargingStation"
    np.testing.assert_array_equal(v0.features.keypoints, fresh.keypoints)
    np.testing.assert_array_equal(v0.features.descriptors, fresh.descriptors)  # uint8 on disk is exact
    assert len(v1.features) == e.keypoints[1] > 0
    index = json.loads((db.folder / INDEX).read_text())
    assert index["format"] == FORMAT == "loci.objects/1"
    assert {o["name"] for o in index["objects"]} == {"television", "charging station"}
    with np.load(db.folder / e.file, allow_pickle=False) as npz:
        assert npz["descriptors"].dtype == np.uint8 and npz["outlines"].shape == (2, 4, 2)


def test_kind_from_name_or_given() -> None:
    assert class_name("television") == "Television"
    assert class_name("charging station") == "ChargingStation"
    assert class_name("coffee_machine") == "CoffeeMachine"
    assert class_name("LivingRoom") == "LivingRoom"
    for bad in ("", "  ", "3d printer", "tv!"):
        with pytest.raises(ValueError, match="--kind"):
            class_name(bad)


def test_adding_appends_pictures_replace_starts_afresh(db: ObjectDatabase) -> None:
    e = db.add("Television", [tex("television", "tv2")])
    assert e.name == "television" and len(e.image_sizes) == 2 and e.kind == "Television"
    with pytest.raises(ValueError, match="already known as a Television"):
        db.add("television", [tex("television")], kind="Monitor")
    e = db.add("television", [tex("monitor")], kind="monitor", replace=True)
    assert e.kind == "Monitor" and len(e.image_sizes) == 1
    assert ObjectDatabase.open(db.folder).entry("television").kind == "Monitor"
    db.remove("television")
    assert ObjectDatabase.open(db.folder).names() == ["charging station"]
    assert not (db.folder / e.file).exists()


def test_bad_input_says_what_to_do(db: ObjectDatabase) -> None:
    with pytest.raises(ValueError, match=r"unknown object 'couch'.*known: charging station, television"):
        db.entry("couch")
    with pytest.raises(ValueError, match="at least one image"):
        db.add("couch", [])
    with pytest.raises(ValueError, match="keypoints"):
        db.add("couch", [np.full((100, 100, 3), 128, np.uint8)])  # a blank picture
    with pytest.raises(ValueError, match="non-empty name"):
        db.add("  ", [tex("couch")])
    assert "couch" not in ObjectDatabase.open(db.folder)
    f = db.folder.parent / "a_file"
    f.write_text("x")
    with pytest.raises(ValueError, match="is a file"):
        ObjectDatabase.open(f)


def test_file_names_are_distinct_and_safe() -> None:
    assert file_name("tv 1") != file_name("tv_1")
    assert file_name("TV 1") == file_name("tv 1")
    assert "/" not in file_name("../../etc/passwd") and file_name("../x").endswith(".npz")


def test_damaged_object_file_is_named_and_the_others_survive(db: ObjectDatabase) -> None:
    tv = db.entry("television")
    path = db.folder / tv.file
    path.write_bytes(path.read_bytes()[:200])  # truncated
    again = ObjectDatabase.open(db.folder)
    with pytest.raises(ModelError, match=r"television.*loci objects add --replace 'television'"):
        again.views()
    assert len(again.views(["charging station"])) == 2
    # teaching another object leaves everything else as it was
    again.add("couch", [tex("couch")])
    assert ObjectDatabase.open(db.folder).names() == ["charging station", "couch", "television"]
    again.add("television", [tex("television")], replace=True)  # the documented fix
    assert len(ObjectDatabase.open(db.folder).views()) == 4


def test_missing_and_foreign_object_files(db: ObjectDatabase) -> None:
    tv = db.entry("television")
    (db.folder / tv.file).unlink()
    with pytest.raises(ModelError, match="features of object 'television' are missing"):
        ObjectDatabase.open(db.folder).views()
    # a pickled array where descriptors belong is refused, never unpickled
    cs = db.entry("charging station")
    with np.load(db.folder / cs.file, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["descriptors"] = np.array([{"evil": 1}], dtype=object)
    np.savez(db.folder / cs.file, **arrays)
    with pytest.raises(ModelError, match="pickled"):
        ObjectDatabase.open(db.folder).views(["charging station"])


def test_damaged_index_is_an_error_and_a_missing_one_is_rebuilt(db: ObjectDatabase) -> None:
    index = db.folder / INDEX
    good = index.read_text()
    index.write_text(good[: len(good) // 2])
    with pytest.raises(ModelError, match=r"index\.json.*untouched"):
        ObjectDatabase.open(db.folder)
    index.write_text(json.dumps({"format": "something/9", "objects": []}))
    with pytest.raises(ModelError, match=r"not a loci\.objects/1 index"):
        ObjectDatabase.open(db.folder)
    index.unlink()
    rebuilt = ObjectDatabase.open(db.folder)
    assert rebuilt.names() == ["charging station", "television"]
    assert rebuilt.entry("charging station").kind == "ChargingStation"
    assert len(rebuilt.views()) == 3


def test_writes_are_atomic(db: ObjectDatabase, monkeypatch: pytest.MonkeyPatch) -> None:
    """A crash while writing (here: fsync fails) leaves the previous files whole and no temp files."""
    before = {p.name: p.read_bytes() for p in db.folder.iterdir()}

    def crash(fd: int) -> None:
        raise OSError("disk pulled out")

    monkeypatch.setattr(os, "fsync", crash)
    with pytest.raises(OSError, match="disk pulled out"):
        db.add("television", [tex("television", "tv3")])
    with pytest.raises(OSError, match="disk pulled out"):
        db.add("couch", [tex("couch")])
    monkeypatch.undo()
    after = {p.name: p.read_bytes() for p in db.folder.iterdir()}
    assert after == before
    again = ObjectDatabase.open(db.folder)
    assert again.names() == ["charging station", "television"] and len(again.views()) == 3
