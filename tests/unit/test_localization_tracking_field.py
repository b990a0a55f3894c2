"""The tracker's incremental likelihood field: the same, cell for cell, as the field made from
scratch on the same map, after every scan, however the map grew."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.localization_world import ANGLES, RANGE_MAX, drifting_odometry, path, scans, world

from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.tracking import PoseTracker, TrackingParams
from knowledge.localization.tracking_field import TrackingField, exact_distance_field
from knowledge.localization.trajectory import ate
from knowledge.metric.mapping import CELL_FREE, CELL_OCCUPIED, CELL_UNKNOWN, MappingParams, ScanMapper

SIGMAS = (0.25, 0.1, 0.05)


def brute_distance(occ: np.ndarray, res: float, max_distance: float) -> np.ndarray:
    """The slow reference: for each cell, the nearest occupied cell by trying them all."""
    out = np.full(occ.shape, np.float32(max_distance), dtype=np.float32)
    iy, ix = np.nonzero(occ)
    for r in range(occ.shape[0]):
        for c in range(occ.shape[1]):
            if iy.size:
                k = int(np.min((iy - r) ** 2 + (ix - c) ** 2))
                out[r, c] = min(np.float32(math.sqrt(k)) * np.float32(res), np.float32(max_distance))
    return out


def test_exact_distances_against_trying_every_obstacle() -> None:
    rng = np.random.default_rng(3)
    for density in (0.0, 0.002, 0.02, 0.3):
        occ = rng.random((37, 53)) < density
        want = brute_distance(occ, 0.05, 1.0)
        assert np.array_equal(exact_distance_field(occ, 0.05, 1.0), want)
        assert np.array_equal(exact_distance_field(occ, 0.1, 0.35), brute_distance(occ, 0.1, 0.35))


def test_a_cells_distance_depends_only_on_the_obstacles_it_can_reach() -> None:
    # OpenCV's precise transform alone rounds differently in different windows (on the CSAIL
    # map, 370 cells² came out as 369.99994 in a tile): the exact field does not
    rng = np.random.default_rng(5)
    occ = rng.random((400, 420)) < 0.01
    whole = exact_distance_field(occ, 0.05, 1.0)
    m = 21  # the reach of a 1 m field at 5 cm
    for r0, c0, h, w in ((0, 0, 64, 64), (100, 37, 64, 128), (300, 350, 100, 70), (150, 150, 1, 1)):
        a0, b0 = max(r0 - m, 0), max(c0 - m, 0)
        part = exact_distance_field(occ[a0 : r0 + h + m, b0 : c0 + w + m], 0.05, 1.0)
        assert np.array_equal(
            part[r0 - a0 : r0 - a0 + h, c0 - b0 : c0 - b0 + w], whole[r0 : r0 + h, c0 : c0 + w]
        )


def _replayed_state(mapper: ScanMapper, changes: list[np.ndarray]) -> dict[tuple[int, int], int]:
    state: dict[tuple[int, int], int] = {}
    for ch in changes:
        for r, c, s in ch:
            state[(int(r), int(c))] = int(s)
    return state


def _lattice_box(mapper: ScanMapper, r0: int, c0: int, rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """The mapper's occupied and free cells of lattice rows r0.., cols c0.. (cell centres asked)."""
    res = mapper.params.resolution
    origin = mapper.lattice_origin
    assert origin is not None
    x0, y0 = origin
    occ, free, _ = mapper.window(
        x0 + (c0 + 0.5) * res,
        y0 + (r0 + 0.5) * res,
        x0 + (c0 + cols - 0.5) * res,
        y0 + (r0 + rows - 0.5) * res,
    )
    assert occ.shape == (rows, cols)
    return occ, free


def test_the_mapper_lists_every_change_in_lattice_cells_that_stay_put() -> None:
    g, truth = world(), path()
    R = scans(g, truth)
    # short beams and a small margin: the grid grows often
    mapper = ScanMapper(MappingParams(margin=0.2, max_range=3.0), changes=True)
    changes, origins, shapes = [], set(), set()
    for i in range(len(truth) - 1, -1, -7):  # backwards: the grid grows to the left
        mapper.add(R[i], ANGLES, truth[i], range_max=RANGE_MAX)
        changes.append(mapper.take_changes())
        origins.add(mapper._origin)
        shapes.add(mapper._hits.shape)
    # the grid grew, once with its origin moving (the lattice cells must not)
    assert len(shapes) > 2 and len(origins) > 1
    state = _replayed_state(mapper, changes)
    rows = [r for r, _ in state]
    cols = [c for _, c in state]
    r0, c0 = min(rows), min(cols)
    occ, free = _lattice_box(mapper, r0, c0, max(rows) - r0 + 1, max(cols) - c0 + 1)
    want = np.where(occ, CELL_OCCUPIED, np.where(free, CELL_FREE, CELL_UNKNOWN))
    got = np.zeros_like(want)
    for (r, c), s in state.items():
        got[r - r0, c - c0] = s
    assert np.array_equal(got, want)
    assert occ.sum() > 100 and free.sum() > 1000
    # nothing more to take; a mapper made without the list refuses
    assert mapper.take_changes().shape == (0, 3)
    with pytest.raises(ValueError, match="changes=True"):
        ScanMapper().take_changes()


def test_the_mapper_grows_in_place_as_it_would_by_copying() -> None:
    g, truth = world(), path()
    R = scans(g, truth)
    in_place = ScanMapper(MappingParams(margin=0.2, max_range=3.0), changes=True)
    copied = ScanMapper(MappingParams(margin=0.2, max_range=3.0), changes=True)
    shapes, first_room = set(), None
    for i in list(range(len(truth) - 1, -1, -5)) + list(range(0, len(truth), 9)):
        copied._room = None  # no room kept: every growth copies the counts into new memory
        for m in (in_place, copied):
            m.add(R[i], ANGLES, truth[i], range_max=RANGE_MAX)
        first_room = first_room or in_place._room
        shapes.add(in_place._hits.shape)
        assert np.array_equal(in_place._hits, copied._hits) and np.array_equal(
            in_place._misses, copied._misses
        )
        assert np.array_equal(in_place.take_changes(), copied.take_changes())
    # it grew many times, to the left and to the right, in the memory it was given first
    assert len(shapes) > 10 and in_place._room is first_room and in_place._origin == copied._origin
    assert np.array_equal(in_place.grid().state, copied.grid().state)


@pytest.mark.parametrize(("every", "reserve"), [(1, 0.0), (5, 0.0), (1, 30.0)])
def test_the_incremental_field_is_the_field_made_from_scratch(every: int, reserve: float) -> None:
    g, truth = world(), path()
    R = scans(g, truth)
    mapper = ScanMapper(MappingParams(margin=0.2, max_range=3.0), changes=True)
    field: TrackingField | None = None
    checked = 0
    for n, i in enumerate(range(len(truth) - 1, -1, -3)):  # the grid grows to the left
        mapper.add(R[i], ANGLES, truth[i], range_max=RANGE_MAX)
        if n % every:
            continue
        if field is None:
            origin = mapper.lattice_origin
            assert origin is not None
            # small tiles and growth steps: many tiles, runs and growths in a small world
            field = TrackingField(origin, 0.05, 1.0, SIGMAS, tile=16, grow=0.5, reserve=reserve)
        field.update(mapper.take_changes())
        rows, cols = field.shape
        occ, free = _lattice_box(mapper, field.row0, field.col0, rows, cols)
        assert np.array_equal(field.occupied, occ) and np.array_equal(field.free, free)
        dist = exact_distance_field(occ, 0.05, 1.0)
        assert np.array_equal(field.distance, dist)
        lf = LikelihoodField(dist, free, occ, 0.05, (0.0, 0.0, 0.0), 1.0)
        for k, s in enumerate(SIGMAS):
            assert np.array_equal(field.scores[k], lf.score(s))
        mf = field.match_field()
        assert mf.scores[0] is not None and mf.field.distance is field.distance
        x0, y0 = mapper.lattice_origin  # type: ignore[misc]
        assert mf.field.origin == pytest.approx((x0 + field.col0 * 0.05, y0 + field.row0 * 0.05, 0.0))
        checked += 1
    assert field is not None and checked > 10
    # with no more room than its own size the field was copied into larger memory; with
    # 30 m of room it grew in place
    assert (field.reallocations > 0) if reserve == 0.0 else (field.reallocations == 0), field.reallocations
    assert field.update(np.zeros((0, 3), dtype=np.int64)) == 0  # nothing changed: nothing redone


def test_a_scan_redoes_only_the_tiles_it_reaches() -> None:
    field = TrackingField((0.0, 0.0), 0.05, 1.0, SIGMAS, tile=16, grow=2.0)
    field.update(np.array([[100, 100, CELL_OCCUPIED]]))
    # the cell and 21 cells around it: rows and columns 79..121, tiles 4..7 each way
    assert field.tiles_updated == 16
    d = field.distance
    r, c = 100 - field.row0, 100 - field.col0
    assert d[r, c] == 0.0 and d[r, c + 10] == pytest.approx(0.5) and d[r + 25, c] == np.float32(1.0)
    # free cells change no distance
    assert field.update(np.array([[10, 10, CELL_FREE], [11, 10, CELL_FREE]])) == 0
    assert field.free[10 - field.row0, 10 - field.col0]
    # an occupied cell that turns free again: the field is as before anything was seen
    field.update(np.array([[100, 100, CELL_FREE]]))
    assert np.all(field.distance == np.float32(1.0))
    assert np.all(field.scores[2] == field.scores[2][0, 0])


def test_the_tracker_tracks_as_well_with_the_incremental_field() -> None:
    g, truth = world(), path()
    R, odo = scans(g, truth), drifting_odometry(truth)
    errs = {}
    for kind in ("incremental", "window"):
        tracker = PoseTracker(TrackingParams(field=kind))
        est = np.array(
            [tracker.update(R[i], ANGLES, odo[i], range_max=RANGE_MAX).pose for i in range(len(odo))]
        )
        errs[kind] = ate(truth, est)[0].rmse
        assert (tracker.tracking_field is not None) == (kind == "incremental")
    assert errs["incremental"] < 0.05 and errs["window"] < 0.05
    with pytest.raises(ValueError, match="field"):
        TrackingParams(field="tiles")


def test_a_first_scan_with_no_echo_leaves_the_field_for_later() -> None:
    g, truth = world(), path()
    R, odo = scans(g, truth), drifting_odometry(truth)
    tracker = PoseTracker()
    first = tracker.update(np.full(ANGLES.shape, np.inf), ANGLES, odo[0], range_max=RANGE_MAX)
    assert tracker.mapper.scans == 1 and tracker.mapper.lattice_origin is None and not first.matched
    steps = [tracker.update(R[i], ANGLES, odo[i], range_max=RANGE_MAX) for i in range(1, 40)]
    assert tracker.tracking_field is not None and sum(s.matched for s in steps) > 20
