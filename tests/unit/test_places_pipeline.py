"""Labelled maps → training scans → a place model → whole-map labels, on generated buildings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from knowledge import labels as lbl
from knowledge.errors import MapError
from knowledge.learning.metrics import score
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.dataset import (
    LabelledMap,
    detect_codes,
    load_ipa_building,
    load_labelled_map,
    sample_cells,
    simulate_scans,
)
from knowledge.places.labeling import class_codes, label_map
from knowledge.places.model import PlaceModel
from knowledge.places.training import TrainingConfig, merge_classes, train_place_model, unlabel_classes
from sim.buildings import generate_building

FAST = TrainingConfig(stride=10, rounds=12, n_beams=90, classes=("room", "corridor", "doorway"))


@pytest.fixture(scope="module")
def buildings() -> list[LabelledMap]:
    out = []
    for seed in (3, 4):
        b = generate_building(seed, layout="straight", hall=False)
        out.append(LabelledMap(b.grid, b.labels))
    return out


@pytest.fixture(scope="module")
def model(buildings: list[LabelledMap]) -> PlaceModel:
    m, _ = train_place_model(buildings[:1], FAST)
    return m


def test_label_codes_are_detected(tmp_path: Path) -> None:
    assert detect_codes(np.array([[0, 77, 115, 179]], np.uint8)) == "ipa"
    assert detect_codes(np.array([[0, 1, 2, 3]], np.uint8)) == "standard"
    # a map whose label image names a code nobody defined is refused with the fix
    grid = OccupancyGrid(np.zeros((4, 4), np.int8), 0.1)
    with pytest.raises(MapError, match="legend"):
        LabelledMap(grid, np.full((4, 4), 9, np.uint8))
    # a legend beside the label image names extra codes
    labels = np.full((4, 4), 9, np.uint8)
    lbl.write_label_image(tmp_path / "l.png", labels, {9: "kitchen"})
    grid.save(tmp_path / "m.yaml")
    lm = load_labelled_map(tmp_path / "m.yaml", tmp_path / "l.png")
    assert lm.class_counts() == {"kitchen": 16}


def test_sample_cells_takes_a_regular_stride(buildings: list[LabelledMap]) -> None:
    cells = sample_cells(buildings[0], 5)
    assert (cells % 5 == 0).all()
    assert buildings[0].labelled_free()[cells[:, 0], cells[:, 1]].all()
    with pytest.raises(ValueError):
        sample_cells(buildings[0], 0)


def test_simulated_scans_carry_their_cells_labels(buildings: list[LabelledMap]) -> None:
    s = simulate_scans(buildings, stride=12, n_beams=36, max_range=20.0)
    assert s.ranges.shape == (len(s), 36)
    assert set(s.maps) == {b.name for b in buildings}
    for i in (0, len(s) // 2, len(s) - 1):
        lm = buildings[int(s.source[i])]
        r, c = s.cells[i]
        assert s.y[i] == lm.names[int(lm.labels[r, c])]
    assert (s.ranges > 0).all() and (s.ranges <= 20.0).all()


def test_merging_classes_renames_labels() -> None:
    b = generate_building(5, hall=True)
    lm = merge_classes(LabelledMap(b.grid, b.labels), {"hallway": "corridor"})
    assert "hallway" not in lm.class_counts()
    assert lm.class_counts()["corridor"] == int(np.isin(b.labels, (lbl.CORRIDOR, lbl.HALLWAY)).sum())
    # or the halls are left out: free, but no longer labelled (nothing is trained on them)
    out = unlabel_classes(LabelledMap(b.grid, b.labels), ["hallway"])
    assert "hallway" not in out.class_counts() and (out.labels[b.labels == lbl.HALLWAY] == 0).all()
    assert out.class_counts()["corridor"] == int((b.labels == lbl.CORRIDOR).sum())
    assert unlabel_classes(lm, ["kitchen"]) is lm


def test_trained_model_labels_every_free_cell(model: PlaceModel, buildings: list[LabelledMap]) -> None:
    assert model.classes == ("room", "corridor", "doorway")
    assert model.scan.n_beams == 90
    assert any(k.startswith("relaxation_") for k in model.extras)
    # every free cell of the training building: 99 % of them were not training examples
    # (transfer to unseen buildings is measured by `make eval`, not here)
    test = buildings[0]
    result = label_map(test.grid, model)
    assert result.labels.shape == test.grid.shape
    assert (result.labels[~test.grid.free] == 0).all()
    assert (result.labels[test.grid.free] > 0).all()
    np.testing.assert_allclose(result.proba.sum(axis=1), 1.0, atol=1e-5)
    truth = np.array([test.names[int(c)] for c in test.labels[result.cells[:, 0], result.cells[:, 1]]])
    s = score(truth, result.predicted(), model.classes)
    # a small, quickly trained model must still do far better than the majority class
    majority = max(np.mean(truth == c) for c in model.classes)
    assert s.accuracy > majority + 0.1, (s.accuracy, majority)
    assert s.accuracy > 0.9


def test_saved_model_gives_the_same_labels(
    model: PlaceModel, buildings: list[LabelledMap], tmp_path: Path
) -> None:
    path = model.save(tmp_path / "m.npz")
    again = PlaceModel.load(path)
    grid = buildings[1].grid
    cells = grid.free_cells()[::97]
    a = label_map(grid, model, cells=cells)
    b = label_map(grid, again, cells=cells)
    np.testing.assert_array_equal(a.labels, b.labels)


def test_class_codes_follow_the_standard_table() -> None:
    assert class_codes(("room", "corridor", "doorway", "hallway")) == {
        "room": 1,
        "corridor": 2,
        "doorway": 3,
        "hallway": 4,
    }
    assert class_codes(("kitchen", "room", "office")) == {"kitchen": 5, "room": 1, "office": 6}


def test_ipa_buildings_load(shared_data: Path) -> None:
    lm = load_ipa_building(shared_data, "Fr52")
    counts = lm.class_counts()
    assert set(counts) == {"room", "corridor", "doorway"}
    assert sum(counts.values()) == int(lm.grid.free.sum())
