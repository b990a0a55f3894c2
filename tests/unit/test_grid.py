"""OccupancyGrid: loading as map_server does, saving, and world ↔ cell transforms."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from knowledge.errors import MapError
from knowledge.metric import FREE, OCCUPIED, UNKNOWN, OccupancyGrid


def _write_png(path: Path, img: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), img)
    return path


def test_thresholds_follow_map_server(tmp_path: Path) -> None:
    # grey 254 → p = 0.004 free; 0 → p = 1 occupied; 205 → p = 0.196 unknown (not < 0.196);
    # 100 → p = 0.61 unknown; 80 → p = 0.686 occupied
    img = np.array([[254, 0, 205], [100, 80, 255]], dtype=np.uint8)
    grid = OccupancyGrid.from_image(_write_png(tmp_path / "m.png", img), 0.05)
    assert grid.state.tolist() == [[FREE, OCCUPIED, UNKNOWN], [UNKNOWN, OCCUPIED, FREE]]
    neg = OccupancyGrid.from_image(tmp_path / "m.png", 0.05, negate=True)
    assert neg.state[0, 0] == OCCUPIED and neg.state[0, 1] == FREE


def test_yaml_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    state = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], dtype=np.int8), size=(17, 23))
    grid = OccupancyGrid(state, 0.1, origin=(-3.0, 2.5, 0.0), name="r")
    yaml_path = grid.save(tmp_path / "sub" / "r.yaml")
    back = OccupancyGrid.load(yaml_path)
    assert np.array_equal(back.state, grid.state)
    assert back.resolution == pytest.approx(0.1)
    assert back.origin == pytest.approx((-3.0, 2.5, 0.0))
    assert not list((tmp_path / "sub").glob(".*.tmp")), "atomic write left a temp file"


def test_yaml_errors_are_clear(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("resolution: 0.05\n")
    with pytest.raises(MapError, match="missing key 'image'"):
        OccupancyGrid.load(bad)
    bad.write_text("image: nothere.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapError, match="cannot read map image"):
        OccupancyGrid.load(bad)
    with pytest.raises(MapError, match="needs its resolution"):
        OccupancyGrid.load(tmp_path / "x.png")


def test_world_cell_transform_lower_left_origin() -> None:
    grid = OccupancyGrid(np.zeros((10, 20), np.int8), 0.5, origin=(1.0, 2.0, 0.0))
    # the lower-left cell is the last row, first column; its centre is origin + res/2
    assert grid.cell_to_world(np.array([9, 0])).tolist() == pytest.approx([1.25, 2.25])
    assert grid.world_to_cell(np.array([1.25, 2.25])).tolist() == [9, 0]
    # the top-right cell
    assert grid.world_to_cell(np.array([1.0 + 9.99, 2.0 + 4.99])).tolist() == [0, 19]
    assert not grid.in_bounds(grid.world_to_cell(np.array([0.9, 2.1])))


@given(
    yaw=st.floats(-math.pi, math.pi),
    ox=st.floats(-50, 50),
    oy=st.floats(-50, 50),
    res=st.sampled_from([0.02, 0.05, 0.1, 1.0]),
)
def test_cell_world_round_trip(yaw: float, ox: float, oy: float, res: float) -> None:
    grid = OccupancyGrid(np.zeros((30, 40), np.int8), res, origin=(ox, oy, yaw))
    cells = np.argwhere(np.ones((30, 40), bool))
    assert np.array_equal(grid.world_to_cell(grid.cell_to_world(cells)), cells)


def test_state_is_validated_and_read_only() -> None:
    with pytest.raises(MapError):
        OccupancyGrid(np.full((3, 3), 7, np.int8), 0.05)
    with pytest.raises(MapError):
        OccupancyGrid(np.zeros((3, 3), np.int8), 0.0)
    grid = OccupancyGrid(np.zeros((3, 3), np.int8), 0.05)
    with pytest.raises(ValueError):
        grid.state[0, 0] = OCCUPIED


def test_ipa_maps_load(shared_data: Path) -> None:
    grid = OccupancyGrid.from_image(shared_data / "ipa" / "labeled" / "lab_intel.map.png", 0.05)
    assert grid.shape == (708, 763)
    assert 250_000 < int(grid.free.sum()) < 350_000
    raw = OccupancyGrid.from_image(shared_data / "ipa" / "raw" / "freiburg_building79.png", 0.05)
    assert raw.unknown.any() and raw.free.any() and raw.occupied.any()


def test_atomic_write_keeps_usual_permissions(tmp_path: Path) -> None:
    from knowledge.fileio import atomic_write_text

    p = atomic_write_text(tmp_path / "a.txt", "x")
    assert p.stat().st_mode & 0o777 == 0o644
    p.chmod(0o600)
    atomic_write_text(p, "y")
    assert p.stat().st_mode & 0o777 == 0o600 and p.read_text() == "y"


@given(
    x=st.floats(-1.0, 3.0),
    y=st.floats(-1.0, 6.0),
    yaw=st.sampled_from([0.0, 0.3, -2.0]),
)
def test_integer_and_continuous_cells_agree(x: float, y: float, yaw: float) -> None:
    grid = OccupancyGrid(np.zeros((10, 20), np.int8), 0.5, origin=(0.0, 0.0, yaw))
    p = np.array([x, y])
    assert grid.world_to_cell(p).tolist() == np.floor(grid.world_to_cell_float(p)).astype(int).tolist()


def test_a_point_on_the_bottom_border_lies_below_the_map() -> None:
    grid = OccupancyGrid(np.zeros((10, 20), np.int8), 0.5)
    # y = 0 is the lower edge of the lowest row: the half-open cells put it just outside
    assert grid.world_to_cell(np.array([0.05, 0.0])).tolist() == [10, 0]
    assert grid.world_to_cell(np.array([0.05, 1e-9])).tolist() == [9, 0]
