"""Simulated drives: tours that keep clear of walls, and the agent's 360° scans along them."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from agent.core.pipeline import PeopleParams, Pipeline, PipelineParams
from drivers.messages import LaserScan, Pose2D
from knowledge.metric.raycast import cast
from knowledge.places.dataset import LabelledMap
from knowledge.places.drives import DriveParams, Sensor, assemble_along, drive_scans, plan_tour, tour_poses
from knowledge.places.model import PlaceModel, default_model_path
from knowledge.places.recipe import Recipe, recipe_scans
from sim.buildings import generate_building


@pytest.fixture(scope="module")
def office() -> LabelledMap:
    b = generate_building(12, layout="L", hall=True)
    return LabelledMap(b.grid, b.labels)


@pytest.fixture(scope="module")
def poses(office: LabelledMap) -> np.ndarray:
    rng = np.random.default_rng(5)
    return tour_poses(plan_tour(office, rng, 6), rng)


def test_tours_keep_their_clearance_and_reach_rooms_and_corridors(
    office: LabelledMap, poses: np.ndarray
) -> None:
    prm = DriveParams()
    clear = ndimage.distance_transform_edt(office.grid.free) * office.grid.resolution
    cells = office.grid.world_to_cell(poses[:, :2])
    # the smoothed path may cut a corner of the lattice path by a few centimetres
    assert clear[cells[:, 0], cells[:, 1]].min() >= prm.clearance - 0.12
    step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    assert step.max() <= prm.step[1] + 0.02
    moving = step > 0.03
    assert np.median(step[moving]) == pytest.approx(0.1, abs=0.03)
    # the robot faces where it drives
    heading = np.arctan2(*np.diff(poses[:, :2], axis=0)[:, ::-1].T)
    err = np.abs(np.angle(np.exp(1j * (heading[moving] - poses[:-1, 2][moving]))))
    assert np.median(err) < math.radians(10)
    # turning on the spot happens (several poses at one position)
    assert (step < 1e-9).sum() > 5
    kinds = set(np.unique(office.labels[cells[:, 0], cells[:, 1]]).tolist())
    assert {1, 2} <= kinds


def test_a_full_turn_sensor_gives_the_cast_scan(office: LabelledMap, poses: np.ndarray) -> None:
    sensor = Sensor(fov=2 * math.pi, n_beams=360, max_range=30.0)
    d = drive_scans(office, poses[:60], np.random.default_rng(0), sensor=sensor)
    assert len(d) > 30 and (d.coverage == 1.0).all()
    want = cast(office.grid, d.poses, n_beams=360, max_range=30.0)
    np.testing.assert_allclose(d.ranges, want, atol=1e-5)
    # labels are the cells' labels
    names = {1: "room", 2: "corridor", 3: "doorway", 4: "hallway"}
    np.testing.assert_array_equal(d.y, [names[int(office.labels[r, c])] for r, c in d.cells])


def test_front_scans_are_assembled_exactly_as_the_agent_does(office: LabelledMap, poses: np.ndarray) -> None:
    """The training drives and the running agent must build the same 360° scans."""
    model = PlaceModel.load(default_model_path())
    sensor = Sensor()
    P = poses[:120]
    front = cast(office.grid, P, n_beams=sensor.n_beams, max_range=sensor.max_range, fov=sensor.fov)
    ours, coverage = assemble_along(front, sensor.angles, P, range_max=sensor.max_range)
    pipe = Pipeline(model, PipelineParams(people=PeopleParams(enabled=False)))
    inc = sensor.fov / (sensor.n_beams - 1)
    for i in range(len(P)):
        scan = LaserScan(0.25 * i, i, "laser", -sensor.fov / 2, inc, sensor.max_range, front[i])
        res = pipe.process(scan, Pose2D(*map(float, P[i]), stamp=0.25 * i))
        np.testing.assert_allclose(res.ranges, ours[i], atol=1e-4, err_msg=f"scan {i}")
        assert res.coverage == pytest.approx(float(coverage[i]), abs=1e-6)
    # the rear half fills in as the robot drives (the first scan also hits its own side walls)
    assert coverage[0] < 0.55 and coverage[-20:].mean() > 0.8


def test_recipe_scans_are_reproducible_and_of_every_kind(office: LabelledMap) -> None:
    recipe = Recipe(grid_stride=12, variants=1, variant_stride=14, drive_goals=3, keep_every=3)
    a = recipe_scans(office, recipe)
    b = recipe_scans(office, recipe)
    np.testing.assert_array_equal(a.ranges, b.ranges)
    assert set(np.unique(a.kind).tolist()) == {"grid", "grid+rand", "drive"}
    assert set(np.unique(a.y).tolist()) <= {"room", "corridor", "doorway"}  # halls became corridors
    assert a.maps == (office.name,) and (a.source == 0).all()
    c = recipe_scans(office, replace(recipe, seed=1))
    assert len(c) != len(a) or not np.array_equal(c.ranges, a.ranges)
    with pytest.raises(ValueError, match="no scans"):
        recipe_scans(office, Recipe(grid_stride=0, variants=1, variant_stride=0, drive_goals=0))
