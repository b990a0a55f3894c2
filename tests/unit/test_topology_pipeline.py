"""The chain labels → relaxation → correction → regions → segments on generated buildings."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from knowledge.errors import ModelError
from knowledge.labels import CORRIDOR, DOORWAY, HALLWAY, ROOM
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.dataset import LabelledMap
from knowledge.places.features import default_feature_names
from knowledge.places.labeling import MapLabels, class_codes
from knowledge.places.model import PlaceModel
from knowledge.places.regions import CorrectionThresholds, extract_regions, thresholds_from_training
from knowledge.places.relaxation import CompatibilityStats
from knowledge.places.training import HALLWAY_AS_CORRIDOR, TrainingConfig, train_place_model
from knowledge.topology.pipeline import (
    TopologyConfig,
    TopologyResult,
    build_topology,
    histogram_image,
    model_relaxation_stats,
    model_thresholds,
    segments_from_regions,
    topology_from_histograms,
)
from knowledge.topology.topomap import dumps, loads
from sim.buildings import generate_building

RES = 0.1
CLASSES = ("room", "corridor", "doorway")


def tiny_config() -> TrainingConfig:
    """A fast model: 72 beams, the raw-beam features only, 10 rounds (a few seconds)."""
    return TrainingConfig(
        classes=CLASSES,
        merge=HALLWAY_AS_CORRIDOR,
        stride=3,
        n_beams=72,
        rounds=10,
        order="heuristic",
        features=tuple(n for n in default_feature_names() if n.startswith("A.")),
    )


@pytest.fixture(scope="module")
def training_map() -> LabelledMap:
    b = generate_building(1, resolution=RES)
    return LabelledMap(b.grid, b.labels)


@pytest.fixture(scope="module")
def tiny_model(training_map: LabelledMap) -> PlaceModel:
    model, _ = train_place_model([training_map], tiny_config())
    return model


@pytest.fixture(scope="module")
def test_building() -> tuple[OccupancyGrid, np.ndarray]:
    b = generate_building(2, resolution=RES)
    truth = np.where(b.labels == HALLWAY, CORRIDOR, b.labels).astype(np.uint8)
    return b.grid, truth


@pytest.fixture(scope="module")
def topo(tiny_model: PlaceModel, test_building: tuple[OccupancyGrid, np.ndarray]) -> TopologyResult:
    return build_topology(test_building[0], tiny_model)


def accuracy(labels: np.ndarray, truth: np.ndarray, free: np.ndarray) -> float:
    return float(np.mean(labels[free] == truth[free]))


# ---------------------------------------------------------------------- end to end
def test_pipeline_end_to_end(
    tiny_model: PlaceModel, test_building: tuple[OccupancyGrid, np.ndarray], topo: TopologyResult
) -> None:
    grid = test_building[0]
    free = grid.free
    r = topo
    assert r.map_labels is not None
    # every free cell is classified, nothing else
    assert len(r.map_labels.cells) == int(free.sum())
    for img in (r.initial, r.relaxed, r.corrected):
        assert img.shape == grid.shape and img.dtype == np.uint8
        assert np.all(img[~free] == 0)
        assert set(np.unique(img[free]).tolist()) <= {ROOM, CORRIDOR, DOORWAY}
    assert np.array_equal(r.initial, r.map_labels.labels)
    assert r.relaxed_proba.shape == (*grid.shape, 4)
    np.testing.assert_allclose(r.relaxed_proba[free].sum(axis=1), 1.0, atol=1e-4)
    # the graph is the corrected labels' regions; thresholds came from the model file
    assert np.array_equal(r.graph.labels(), r.corrected)
    assert r.thresholds_source == "model"
    assert r.thresholds == model_thresholds(tiny_model)[0]
    # segments: region ids of places only, and (grown) they cover every free cell
    place_ids = {reg.id for reg in r.graph.regions if reg.label != DOORWAY}
    assert set(np.unique(r.segments).tolist()) - {0} <= place_ids
    assert np.all(r.segments[free] > 0)
    assert np.all(r.segments[~free] == 0)
    assert set(r.timings) == {"label", "relax", "correct", "regions", "segments", "total"}
    assert r.timings["total"] >= r.timings["label"] > 0
    doc = loads(dumps(r.document({"model": "tiny"})))
    assert len(doc["nodes"]) == len(r.graph.regions)
    assert doc["meta"]["relaxation"]["iterations"] == 50
    assert doc["meta"]["model"] == "tiny"
    assert doc["thresholds"] == r.thresholds.to_dict()
    assert sum(r.regions_per_class().values()) == len(r.graph.regions)


def test_relaxation_and_correction_improve_accuracy(
    test_building: tuple[OccupancyGrid, np.ndarray], topo: TopologyResult
) -> None:
    grid, truth = test_building
    free = grid.free
    r = topo
    a0 = accuracy(r.initial, truth, free)
    a1 = accuracy(r.relaxed, truth, free)
    a2 = accuracy(r.corrected, truth, free)
    assert a1 > a0 + 0.005, (a0, a1)
    assert a2 >= a1 - 0.002, (a1, a2)
    # and the labels become less fragmented: far fewer regions after relaxation + correction
    assert len(extract_regions(r.initial, grid).regions) > 3 * len(r.graph.regions)


def test_config_switches(
    tiny_model: PlaceModel, test_building: tuple[OccupancyGrid, np.ndarray], topo: TopologyResult
) -> None:
    grid, _ = test_building
    stats = model_relaxation_stats(tiny_model)
    assert topo.map_labels is not None
    P0 = histogram_image(topo.map_labels, stats)
    r0 = topology_from_histograms(
        grid, P0, stats, TopologyConfig(iterations=0, correct=False, grow_segments=False)
    )
    assert np.array_equal(r0.initial, r0.relaxed)
    assert np.array_equal(r0.relaxed, r0.corrected)
    assert r0.thresholds is None and r0.merges == () and r0.thresholds_source == "none"
    # doorway cells are no segment without growing
    assert np.all(r0.segments[r0.corrected == DOORWAY] == 0)
    th = CorrectionThresholds(place_min_area_m2=50.0)
    r1 = topology_from_histograms(grid, P0, stats, TopologyConfig(iterations=5, thresholds=th))
    assert r1.thresholds == th and r1.thresholds_source == "config"
    assert all(
        reg.area_m2 > 50.0 for reg in r1.graph.regions if reg.label != DOORWAY and r1.graph.neighbours(reg.id)
    )


# ---------------------------------------------------------------------- the model's parts
def test_thresholds_are_saved_at_training(
    tiny_model: PlaceModel, training_map: LabelledMap, tmp_path: Path
) -> None:
    th, source = model_thresholds(tiny_model)
    assert source == "model"
    expected = thresholds_from_training(
        [training_map.labels], RES
    )  # hallway merged into corridor: same areas
    assert th.doorway_min_area_m2 == expected.doorway_min_area_m2
    path = tiny_model.save(tmp_path / "m.npz")
    again = PlaceModel.load(path)
    assert model_thresholds(again) == (th, "model")
    assert model_relaxation_stats(again).classes == model_relaxation_stats(tiny_model).classes
    bare = dataclasses.replace(tiny_model, extras_meta={})
    assert model_thresholds(bare) == (CorrectionThresholds(), "book")


def test_model_without_relaxation_stats_is_a_clear_error(
    tiny_model: PlaceModel, test_building: tuple[OccupancyGrid, np.ndarray]
) -> None:
    bare = dataclasses.replace(tiny_model, extras={})
    with pytest.raises(ModelError, match=r"no relaxation statistics.*retrain"):
        build_topology(test_building[0], bare, model_name="old.npz")


def test_histogram_columns_follow_the_statistics(tiny_model: PlaceModel) -> None:
    stats = model_relaxation_stats(tiny_model)
    cells = np.array([[0, 0], [1, 2]])
    classes = ("doorway", "room", "corridor")
    proba = np.array([[0.7, 0.2, 0.1], [0.1, 0.3, 0.6]], np.float32)
    ml = MapLabels(np.zeros((2, 3), np.uint8), cells, proba, classes, class_codes(classes))
    P = histogram_image(ml, stats)
    assert stats.classes == (ROOM, CORRIDOR, DOORWAY)
    np.testing.assert_allclose(P[0, 0], [0.2, 0.1, 0.7])
    np.testing.assert_allclose(P[1, 2], [0.3, 0.6, 0.1])
    assert not P[0, 1].any()


def test_confident_histograms_do_not_change() -> None:
    """Eq. 4.6 only multiplies: a one-hot histogram stays one-hot, whatever its neighbours."""
    b = generate_building(3, resolution=0.2, furniture=False)
    truth = np.where(b.labels == HALLWAY, CORRIDOR, b.labels).astype(np.uint8)
    stats = CompatibilityStats.from_label_images([(truth, ~b.grid.free)], (ROOM, CORRIDOR, DOORWAY))
    onehot = np.zeros((*truth.shape, 3), np.float32)
    for i, code in enumerate(stats.classes):
        onehot[..., i] = truth == code
    r = topology_from_histograms(b.grid, onehot, stats, TopologyConfig(correct=False))
    assert np.array_equal(r.relaxed, truth)


# ---------------------------------------------------------------------- segments
def _two_rooms() -> tuple[np.ndarray, np.ndarray]:
    """Two rooms joined by a doorway through a wall; a closed cupboard of free cells."""
    free = np.zeros((12, 24), bool)
    free[1:11, 1:10] = True
    free[1:11, 11:20] = True
    free[5:7, 10] = True  # the opening in the wall at column 10
    lab = np.where(free, ROOM, 0).astype(np.uint8)
    lab[5:7, 8:13] = DOORWAY
    lab[1:3, 1:3] = 0  # unlabelled free corner: grown into the left room
    free[5, 22] = True  # a closed cupboard: free, unlabelled, walled off
    return free, lab


def test_segments_grow_through_free_space_only() -> None:
    free, lab = _two_rooms()
    grid = OccupancyGrid.from_masks(~free, 0.1)
    graph = extract_regions(lab, grid)
    rooms = sorted(reg.id for reg in graph.regions if reg.label == ROOM)
    assert len(rooms) == 2
    bare = segments_from_regions(graph, free, grow=False)
    assert np.all(bare[lab == DOORWAY] == 0)
    assert set(np.unique(bare).tolist()) == {0, *rooms}
    grown = segments_from_regions(graph, free)
    # each doorway cell joins the room on its own side of the wall; the corner joins the left room
    left, right = graph.ids[5, 2], graph.ids[5, 18]
    assert np.all(grown[5:7, 8:10] == left) and np.all(grown[5:7, 11:13] == right)
    assert np.all(grown[1:3, 1:3] == left)
    # a free cell that free space does not connect to any segment stays 0
    assert grown[5, 22] == 0
    assert np.all(grown[free & (lab > 0)] > 0) and np.all(grown[~free] == 0)


def test_config_is_validated() -> None:
    with pytest.raises(ValueError, match="iterations"):
        TopologyConfig(iterations=-1)
    with pytest.raises(ValueError, match="connectivity"):
        TopologyConfig(connectivity=6)
    with pytest.raises(ValueError, match="border"):
        TopologyConfig(border="mirror")  # type: ignore[arg-type]
