"""The whole-map iAMN (Sect. 4.6) on a small drawn office: train on the left half, label the
right half; the model file; the errors a user meets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.drawn_office import drawn_office

from knowledge import labels as lbl
from knowledge.errors import MapError, ModelError
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.dataset import LabelledMap
from knowledge.places.iamn import (
    IAMNConfig,
    IAMNModel,
    check_classes,
    cross_transform,
    label_map_iamn,
    lattice,
    relative,
    train_iamn,
)
from knowledge.places.nn_transform import NNTransform


@pytest.fixture(scope="module")
def office() -> LabelledMap:
    return drawn_office()


@pytest.fixture(scope="module")
def trained(office: LabelledMap) -> tuple[IAMNModel, np.ndarray]:
    left = np.zeros(office.grid.shape, bool)
    left[:, : office.grid.shape[1] // 2] = True
    model, _ = train_iamn(office, IAMNConfig(n_features=12, epochs=60), mask=left)
    return model, left


def test_lattice_puts_one_node_per_block_on_a_free_cell(office: LabelledMap) -> None:
    lat = lattice(office.grid, 0.2)
    assert lat.step == 2
    assert np.all(office.grid.free[lat.cells[:, 0], lat.cells[:, 1]])
    assert len({tuple(b) for b in lat.blocks.tolist()}) == len(lat.blocks)
    assert np.array_equal(lat.free // 2, lat.blocks[lat.node_of])  # every free cell maps to its block's node
    assert len(lat.free) == int(office.grid.free.sum())


def test_trains_and_labels_the_unseen_half(
    office: LabelledMap, trained: tuple[IAMNModel, np.ndarray]
) -> None:
    model, left = trained
    assert model.classes == ("corridor", "doorway", "room")
    assert len(model.feature_names) == 12 and len(set(model.feature_names)) == 12
    assert np.all(model.amn.w_edge_ >= 0)
    result, lat, nodes = label_map_iamn(office.grid, model, mask=~left)
    truth = office.labels[result.cells[:, 0], result.cells[:, 1]]
    pred = result.labels[result.cells[:, 0], result.cells[:, 1]]
    rc = np.isin(truth, (lbl.ROOM, lbl.CORRIDOR))
    assert np.mean(pred[rc] == truth[rc]) > 0.9
    assert not np.any(result.labels[:, : office.grid.shape[1] // 2])  # only inside the mask
    assert result.proba.shape == (len(result.cells), 3)
    assert np.allclose(result.proba.sum(axis=1), 1.0)
    assert len(nodes) == len(lat.cells)


def test_model_file_round_trip(
    tmp_path: Path, office: LabelledMap, trained: tuple[IAMNModel, np.ndarray]
) -> None:
    model, left = trained
    path = model.save(tmp_path / "m.npz")
    again = IAMNModel.load(path)
    assert again.classes == model.classes and again.feature_names == model.feature_names
    assert np.allclose(again.amn.w_node_, model.amn.w_node_)
    a, _, _ = label_map_iamn(office.grid, model, mask=~left)
    b, _, _ = label_map_iamn(office.grid, again, mask=~left)
    assert np.array_equal(a.labels, b.labels)
    with np.load(path, allow_pickle=False) as z:  # no pickles: it loads without allow_pickle
        assert "header_json" in z.files and "nn_X" in z.files


def test_clear_errors(tmp_path: Path, office: LabelledMap, trained: tuple[IAMNModel, np.ndarray]) -> None:
    model, _ = trained
    walls = OccupancyGrid.from_masks(np.ones((20, 20), bool), 0.1, name="all-walls")
    with pytest.raises(MapError, match="no free cells"):
        label_map_iamn(walls, model)
    with pytest.raises(ModelError, match="hallway"):
        check_classes(model, ["room", "hallway"])
    check_classes(model, ["room", "doorway"])
    from knowledge.places.model import default_map_model_path

    with pytest.raises(ModelError, match="AdaBoost place model"):
        IAMNModel.load(default_map_model_path())
    with pytest.raises(ModelError, match="no such model"):
        IAMNModel.load(tmp_path / "missing.npz")


def test_cross_transform_reads_each_fold_against_the_others() -> None:
    rng = np.random.default_rng(0)
    X = rng.normal(size=(80, 3))
    y = np.tile([0, 1], 40)
    groups = np.repeat([0, 1], 40)
    T = cross_transform(X, y, np.zeros((80, 2), int), 2, 1, ("a", "b"), groups=groups)
    other = NNTransform(1).fit(X[40:], y[40:])
    assert np.allclose(T[:40], relative(other.transform(X[:40])))
    with pytest.raises(ValueError, match="hold no"):
        cross_transform(X, np.repeat([0, 1], 40), np.zeros((80, 2), int), 2, 1, ("a", "b"), groups=groups)


def test_trains_on_several_maps(office: LabelledMap) -> None:
    flipped = LabelledMap(
        OccupancyGrid.from_masks(office.grid.occupied[:, ::-1], 0.1, name="flipped"), office.labels[:, ::-1]
    )
    model, _ = train_iamn([office, flipped], IAMNConfig(n_features=8, epochs=30, scales=(10.0,)))
    assert model.data.maps == ("drawn-office", "flipped")
    assert sum(model.data.examples_per_class.values()) == 2 * len(lattice(office.grid, 0.2).cells)
    with pytest.raises(ValueError, match="without a mask"):
        train_iamn([office, flipped], mask=np.ones(office.grid.shape, bool))
