"""``loci places topology`` and ``loci places segment-score`` as a user types them."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from support import cli

from agent.cli import main
from knowledge import labels as lbl
from knowledge.labels import CLASS_COLORS_BGR
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.model import PlaceModel
from knowledge.topology.segmentation_score import gt_rooms
from knowledge.topology.topomap import loads
from sim.buildings import DOOR_ID_BASE, generate_building

REPO = Path(__file__).resolve().parents[2]
RES = 0.1


def loci(*args: str | Path, check: bool = True) -> subprocess.CompletedProcess[str]:
    return cli.loci("-q", *args, check=check)


def read(path: Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    img = cv2.imread(str(path), flags)
    assert img is not None, f"{path} is missing or not an image"
    return np.asarray(img)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("topology_cli")


@pytest.fixture(scope="module")
def model_file(workdir: Path) -> Path:
    """A tiny model trained through the CLI on a generated building saved as a map_server map."""
    b = generate_building(11, resolution=RES)
    b.grid.save(workdir / "train.yaml")
    lbl.write_label_image(workdir / "train.labels.png", b.labels)
    out = workdir / "tiny.npz"
    loci(
        "places", "train", "--map", workdir / "train.yaml", "--labels", workdir / "train.labels.png",
        "--merge", "hallway=corridor", "--classes", "room,corridor,doorway",
        "--stride", "3", "--beams", "72", "--rounds", "8", "--order", "heuristic", "--out", out,
    )  # fmt: skip
    return out


@pytest.fixture(scope="module")
def test_map(workdir: Path) -> tuple[Path, Path]:
    """A second building as a map_server map, and its room segmentation as a GT picture."""
    b = generate_building(12, resolution=RES)
    yaml_path = b.grid.save(workdir / "test.yaml")
    gt = np.where((b.spaces > 0) & (b.spaces < DOOR_ID_BASE), 255, 0).astype(np.uint8)
    gt_path = workdir / "test_gt_segmentation.png"
    cv2.imwrite(str(gt_path), gt)
    return yaml_path, gt_path


@pytest.fixture(scope="module")
def topology_run(model_file: Path, test_map: tuple[Path, Path], workdir: Path) -> tuple[Path, dict[str, Any]]:
    out = workdir / "topo"
    proc = loci("places", "topology", test_map[0], "--model", model_file, "--out-dir", out, "--json")
    return out, json.loads(proc.stdout)


@pytest.mark.slow
def test_topology_writes_every_output(
    topology_run: tuple[Path, dict[str, Any]], test_map: tuple[Path, Path]
) -> None:
    out, summary = topology_run
    state = read(test_map[0].with_suffix(".pgm"), cv2.IMREAD_GRAYSCALE)
    free: np.ndarray = state == 254
    for name in ("labels", "relaxed", "corrected"):
        img = read(out / f"{name}.png", cv2.IMREAD_UNCHANGED)
        assert img.dtype == np.uint8 and img.shape == state.shape
        assert set(np.unique(img[free]).tolist()) <= {1, 2, 3}
        assert np.all(img[~free] == 0)
    regions = read(out / "regions.png", cv2.IMREAD_UNCHANGED)
    assert regions.dtype == np.uint16 and regions.shape == state.shape
    segments = read(out / "segments.png", cv2.IMREAD_UNCHANGED)
    assert segments.dtype == np.uint16
    doc = loads((out / "topomap.json").read_text())
    assert doc["schema"] == "loci.topomap/1"
    ids = {n["id"] for n in doc["nodes"]}
    assert set(np.unique(regions).tolist()) - {0} == ids
    # each node's cell count is its number of pixels in regions.png
    counts = np.bincount(regions.ravel())
    assert all(counts[n["id"]] == n["cells"] for n in doc["nodes"])
    place_ids = {n["id"] for n in doc["nodes"] if n["label"] in ("room", "corridor")}
    assert set(np.unique(segments).tolist()) - {0} <= place_ids
    assert np.all(segments[free] > 0)
    corrected = read(out / "corrected.png", cv2.IMREAD_UNCHANGED)
    code_of = {n["id"]: n["code"] for n in doc["nodes"]}
    lut = np.zeros(regions.max() + 1, np.uint8)
    for i, c in code_of.items():
        lut[i] = c
    assert np.array_equal(lut[regions], corrected)
    overview = read(out / "overview.png", cv2.IMREAD_COLOR)
    assert overview.shape[0] > 100
    # a map_server YAML beside each image, placing it where the input map lies
    source = OccupancyGrid.from_yaml(test_map[0])
    for name in ("labels", "relaxed", "corrected", "regions", "segments"):
        meta = yaml.safe_load((out / f"{name}.yaml").read_text())
        assert meta["image"] == f"{name}.png" and meta["mode"] == "raw"
        assert meta["resolution"] == source.resolution and tuple(meta["origin"]) == source.origin
    # the overview's legend shows the colour of every class in the corrected labels
    legend = overview[-40:]
    for code in set(np.unique(corrected).tolist()) - {0}:
        assert np.all(legend == np.asarray(CLASS_COLORS_BGR[code], np.uint8), axis=2).any()
    # the printed summary matches the files
    assert summary["regions"] == len(doc["nodes"]) and summary["edges"] == len(doc["edges"])
    assert sum(summary["regions_per_class"].values()) == len(doc["nodes"])
    assert summary["free_cells"] == int(free.sum())
    assert summary["correction"]["thresholds_source"] == "model"
    assert doc["thresholds"] == summary["correction"]["thresholds"]
    assert set(summary["timings_s"]) >= {"label", "relax", "correct", "regions", "total"}
    assert summary["files"]["graph"] == str(out / "topomap.json")


@pytest.mark.slow
def test_topology_text_summary(model_file: Path, test_map: tuple[Path, Path], workdir: Path) -> None:
    out = workdir / "topo_text"
    proc = loci(
        "places", "topology", test_map[0], "--model", model_file, "--out-dir", out,
        "--iterations", "5", "--no-correction", "--no-grow",
    )  # fmt: skip
    text = proc.stdout
    assert "relaxation: 5 iterations" in text
    assert "correction: skipped" in text
    assert "regions:" in text and "edges:" in text and "time: label" in text
    doc = loads((out / "topomap.json").read_text())
    assert doc["thresholds"] is None and doc["corrections"] == []
    segments = read(out / "segments.png", cv2.IMREAD_UNCHANGED)
    corrected = read(out / "corrected.png", cv2.IMREAD_UNCHANGED)
    assert np.all(segments[corrected == lbl.DOORWAY] == 0)


def test_segment_score_of_a_topology_run(
    topology_run: tuple[Path, dict[str, Any]], test_map: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    out, _ = topology_run
    proc = loci("places", "segment-score", out / "segments.png", test_map[1], "--json")
    s = json.loads(proc.stdout)
    gt = read(test_map[1], cv2.IMREAD_GRAYSCALE)
    assert s["rooms"] == int(gt_rooms(gt).max()) > 3
    for key in ("recall_mean", "precision_mean", "recall_pooled", "precision_pooled"):
        assert 0.0 < s[key] <= 1.0
    assert len(s["room_recall"]) == s["rooms"]
    # the bare regions, doorway nodes excluded through the graph: fewer pixels in segments
    proc = loci(
        "places", "segment-score", out / "regions.png", test_map[1], "--graph", out / "topomap.json", "--json"
    )
    bare = json.loads(proc.stdout)
    assert sum(bare["segment_px"]) < sum(s["segment_px"])
    assert main(["places", "segment-score", str(out / "segments.png"), str(test_map[1])]) == 0
    text = capsys.readouterr().out
    assert "recall" in text and "precision" in text and "pooled" in text


def test_segment_score_of_a_real_ground_truth_against_itself(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    gt_path = shared_data / "ipa" / "segmentation" / "lab_ipa_gt_segmentation.png"
    rooms = gt_rooms(read(gt_path, cv2.IMREAD_UNCHANGED))
    seg = tmp_path / "rooms.png"
    cv2.imwrite(str(seg), rooms.astype(np.uint16))
    s = json.loads(loci("places", "segment-score", seg, gt_path, "--json").stdout)
    assert s["rooms"] == s["segments"] == int(rooms.max()) > 5
    assert s["recall_mean"] == s["precision_mean"] == s["recall_pooled"] == s["precision_pooled"] == 1.0
    # one segment for the whole map: it covers every room (recall 1) but is mostly not any one room
    cv2.imwrite(str(seg), (rooms > 0).astype(np.uint16))
    assert main(["places", "segment-score", str(seg), str(gt_path), "--json"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert one["segments"] == 1 and one["recall_mean"] == 1.0 and one["precision_mean"] < 0.5


def test_clear_errors(
    model_file: Path, test_map: tuple[Path, Path], workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    old = PlaceModel.load(model_file)
    old.extras.clear()
    old.save(workdir / "old.npz")
    proc = loci(
        "places", "topology", test_map[0], "--model", workdir / "old.npz", "--out-dir", workdir / "x", check=False
    )  # fmt: skip
    assert proc.returncode == 2
    assert "no relaxation statistics" in proc.stderr and "loci places train" in proc.stderr
    small = workdir / "small.png"
    cv2.imwrite(str(small), np.zeros((5, 5), np.uint16))
    assert main(["-q", "places", "segment-score", str(small), str(test_map[1])]) == 2
    assert "same map" in capsys.readouterr().err
    missing = str(workdir / "nothing.png")
    assert (
        main(["-q", "places", "topology", missing, "--resolution", "0.05", "--out-dir", str(workdir / "y")])
        == 2
    )
    assert "cannot read" in capsys.readouterr().err
    assert main(["-q", "places", "segment-score", missing, str(test_map[1])]) == 2
    assert "cannot read" in capsys.readouterr().err
