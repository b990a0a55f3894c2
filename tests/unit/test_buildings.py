"""Generated office buildings: determinism, labelling, doors, connectivity, sizes, layouts, realism.

Every size is measured from the arrays (cells × resolution), not read back from parameters.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from knowledge.labels import CORRIDOR, DOORWAY, HALLWAY, IPA_CODES, ROOM, read_label_image
from sim.buildings import (
    DOOR_ID_BASE,
    LAYOUTS,
    Building,
    generate_building,
    generate_tour_office,
    label_building_png,
)

RES = 0.05


@pytest.fixture(scope="module")
def bare() -> list[Building]:
    """One unfurnished building per layout, with and without a hall (for geometry)."""
    return [
        generate_building(100 + i, layout=layout, hall=hall, furniture=False)
        for i, layout in enumerate(LAYOUTS)
        for hall in (False, True)
    ]


@pytest.fixture(scope="module")
def furnished(bare: list[Building]) -> list[Building]:
    """The same buildings, furnished densely, plus a few with everything drawn from the seed."""
    out = [generate_building(**{**b.params, "furniture": True, "furniture_density": 2.0}) for b in bare]
    return out + [generate_building(seed) for seed in range(4)]


def _same(a: Building, b: Building) -> bool:
    return (
        np.array_equal(a.grid.state, b.grid.state)
        and np.array_equal(a.labels, b.labels)
        and np.array_equal(a.spaces, b.spaces)
        and a.doors == b.doors
        and a.rooms == b.rooms
        and a.corridors == b.corridors
        and a.furniture == b.furniture
    )


# ---------------------------------------------------------------------- determinism
def test_same_seed_and_options_give_identical_buildings() -> None:
    a = generate_building(7, living_room=True, bucket=True)
    b = generate_building(7, living_room=True, bucket=True)
    assert _same(a, b)
    # params hold everything needed to regenerate it
    assert _same(generate_building(**a.params), a)


def test_different_seeds_differ() -> None:
    a, b = generate_building(1, layout="straight"), generate_building(2, layout="straight")
    assert a.grid.shape != b.grid.shape or not np.array_equal(a.labels, b.labels)


def test_furniture_does_not_change_walls_or_doors(bare: list[Building], furnished: list[Building]) -> None:
    for plain, full in zip(bare, furnished, strict=False):
        assert plain.doors == full.doors and plain.rooms[0].rects == full.rooms[0].rects
        assert len(full.furniture) > len(plain.furniture) == 0
        # furniture only takes cells away from the free space
        assert not (full.grid.free & ~plain.grid.free).any()
        assert (plain.grid.free & ~full.grid.free).any()


# ---------------------------------------------------------------------- labels and spaces
def _check_labelling(b: Building) -> None:
    free = b.grid.free
    assert (b.labels[free] > 0).all(), "every free cell is labelled"
    assert (b.labels[~free] == 0).all(), "labels only on free cells"
    assert set(np.unique(b.labels[free])) <= {ROOM, CORRIDOR, DOORWAY, HALLWAY}
    assert (b.spaces[free] > 0).all() and (b.spaces[~free] == 0).all()
    # door-opening cells are doorway; room, corridor and hall cells keep their class unless
    # the doorway rectangle covers them
    doors = b.spaces >= DOOR_ID_BASE
    assert (b.labels[doors] == DOORWAY).all()
    for r in (*b.rooms, *b.corridors):
        assert set(np.unique(b.labels[b.spaces == r.id])) <= {r.label, DOORWAY}


def _check_connected(b: Building) -> None:
    """All free space is one 4-connected region: no sealed room, no pocket behind furniture."""
    n, _ = cv2.connectedComponents(b.grid.free.astype(np.uint8), connectivity=4)
    assert n == 2
    present = set(np.unique(b.spaces[b.grid.free]).tolist())
    assert {r.id for r in (*b.rooms, *b.corridors)} <= present
    assert {d.id for d in b.doors} <= present


def _check_doors(b: Building) -> None:
    free = b.grid.free
    for d in b.doors:
        opening = b.spaces == d.id
        assert opening.any()
        assert (b.labels[opening] == DOORWAY).all()
        # the door's centre lies in its opening
        r, c = b.grid.world_to_cell(np.array(d.center))
        assert b.spaces[r, c] == d.id
        # width along the wall and depth through it, measured on the opening's cells
        rows, cols = np.nonzero(opening)
        across_rows = math.isclose(abs(math.sin(d.orientation)), 1.0, abs_tol=1e-6)
        width = (np.ptp(cols) + 1 if across_rows else np.ptp(rows) + 1) * b.grid.resolution
        depth = (np.ptp(rows) + 1 if across_rows else np.ptp(cols) + 1) * b.grid.resolution
        res = b.grid.resolution
        assert 0.8 - res - 1e-9 <= width <= 1.2 + res + 1e-9, width
        assert 0.1 - res - 1e-9 <= depth <= 0.4 + 1e-9, depth
        # flood fill through the door and the two spaces only: both are reached from the opening
        a, other = d.connects
        mask = free & np.isin(b.spaces, [a, other, d.id])
        _, cc = cv2.connectedComponents(mask.astype(np.uint8), connectivity=4)
        comp = cc == cc[rows[0], cols[0]]
        assert (b.spaces[comp] == a).any() and (b.spaces[comp] == other).any()
        # the normal points from connects[0] into connects[1]
        step = np.array([math.cos(d.orientation), math.sin(d.orientation)])
        for sign, sid in ((-1, a), (1, other)):
            p = np.array(d.center) + sign * (d.wall_thickness / 2 + 0.1) * step
            pr, pc = b.grid.world_to_cell(p)
            assert b.spaces[pr, pc] == sid


def test_labels_spaces_doors_and_connectivity(furnished: list[Building]) -> None:
    for b in furnished:
        _check_labelling(b)
        _check_connected(b)
        _check_doors(b)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), density=st.sampled_from([0.0, 1.0, 3.0]))
def test_invariants_hold_for_any_seed(seed: int, density: float) -> None:
    b = generate_building(seed, furniture_density=density)
    _check_labelling(b)
    _check_connected(b)
    _check_doors(b)


def test_furniture_never_blocks_a_door(bare: list[Building], furnished: list[Building]) -> None:
    for plain, full in zip(bare, furnished, strict=False):
        taken = plain.grid.free & ~full.grid.free
        assert taken.any()
        k = np.ones((2 * round(0.3 / RES) + 1,) * 2, np.uint8)
        for d in full.doors:
            near = cv2.dilate((full.spaces == d.id).astype(np.uint8), k) > 0
            assert not (taken & near).any(), f"furniture within 0.3 m of door {d.id}"


# ---------------------------------------------------------------------- sizes
def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell of ``mask``: length of its horizontal and vertical run of mask cells."""

    def along_rows(m: np.ndarray) -> np.ndarray:
        out = np.zeros(m.shape, dtype=np.int64)
        for i, row in enumerate(m):
            padded = np.concatenate([[0], row.astype(np.int8), [0]])
            edges = np.flatnonzero(np.diff(padded))
            for s, e in zip(edges[::2], edges[1::2], strict=True):
                out[i, s:e] = e - s
        return out

    return along_rows(mask), along_rows(mask.T).T


def test_room_corridor_and_door_sizes_are_in_range(bare: list[Building]) -> None:
    for b in bare:
        res = b.grid.resolution
        for r in b.rooms:
            rows, cols = np.nonzero(b.spaces == r.id)
            # a room is a rectangle: its cells fill their bounding box
            h, w = (np.ptp(rows) + 1) * res, (np.ptp(cols) + 1) * res
            if r.kind == "room":
                assert rows.size == round(h / res) * round(w / res)
                assert 2.5 - res - 1e-9 <= min(h, w) <= 8.0 + 1e-9, (r, h, w)
                assert max(h, w) <= 12.0 + res + 1e-9, (r, h, w)
        for c in b.corridors:
            horiz, vert = _runs(b.spaces == c.id)
            width = np.minimum(horiz, vert)[b.spaces == c.id] * res
            assert 1.5 - res - 1e-9 <= np.median(width) <= 3.0 + 1e-9
            assert np.percentile(width, 5) >= 1.5 - res - 1e-9
    # doors: measured in _check_doors; the widths vary
    widths = [d.width for b in bare for d in b.doors]
    assert min(widths) >= 0.8 - 1e-9 and max(widths) <= 1.2 + 1e-9 and np.ptp(widths) >= 0.15


def test_walls_vary_in_thickness(bare: list[Building]) -> None:
    depths = {round(d.wall_thickness, 2) for b in bare for d in b.doors}
    assert min(depths) >= 0.1 - 1e-9 and max(depths) <= 0.35 + 1e-9 and len(depths) >= 3


def test_other_resolutions_keep_sizes_in_metres() -> None:
    b = generate_building(3, resolution=0.1, furniture=False)
    _check_labelling(b)
    _check_connected(b)
    _check_doors(b)
    assert b.grid.resolution == 0.1
    for r in b.rooms:
        if r.kind == "room":
            rows, cols = np.nonzero(b.spaces == r.id)
            assert min(np.ptp(rows) + 1, np.ptp(cols) + 1) * 0.1 >= 2.4


# ---------------------------------------------------------------------- layouts
def _shape_of(mask: np.ndarray) -> tuple[int, int]:
    """(regions of the bounding box outside ``mask`` that reach the box's border, holes in ``mask``)."""
    rows, cols = np.nonzero(mask)
    sub = mask[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    n, cc = cv2.connectedComponents((~sub).astype(np.uint8), connectivity=4)
    border = set(np.unique(np.concatenate([cc[0], cc[-1], cc[:, 0], cc[:, -1]])).tolist()) - {0}
    return len(border), n - 1 - len(border)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_each_layout_builds_the_corridor_it_names(layout: str) -> None:
    for seed in (11, 12):
        b = generate_building(seed, layout=layout, hall=False, furniture=False)
        assert b.params["layout"] == layout
        assert len(b.corridors) == 1 and not b.halls
        corridor = b.spaces == b.corridors[0].id
        outer, holes = _shape_of(corridor)
        expected = {"straight": (0, 0), "L": (1, 0), "T": (2, 0), "loop": (0, 1)}[layout]
        assert (outer, holes) == expected, (layout, seed, outer, holes)
        assert not (b.labels == HALLWAY).any()


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_requested_hall_is_an_open_space_beside_the_corridors(layout: str) -> None:
    b = generate_building(21, layout=layout, hall=True, furniture=False)
    assert len(b.halls) == 1
    hall = b.spaces == b.halls[0].id
    assert (b.labels[hall] == HALLWAY).any()
    assert hall.sum() * RES**2 >= 20.0
    # open onto a corridor: some hall cell has a corridor cell as 4-neighbour
    corridor = np.isin(b.spaces, [c.id for c in b.corridors])
    grown = cv2.dilate(hall.astype(np.uint8), np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8)) > 0
    assert (grown & corridor).any()


def test_layout_none_draws_every_layout_and_halls_sometimes() -> None:
    seen = [generate_building(s, furniture=False) for s in range(16)]
    assert {b.params["layout"] for b in seen} == set(LAYOUTS)
    assert 0 < sum(b.params["hall"] for b in seen) < len(seen)


# ---------------------------------------------------------------------- options, tour, pictures
def test_outside_is_unknown_or_occupied_and_walls_are_closed() -> None:
    b = generate_building(5, furniture=False)
    unknown = b.grid.unknown
    assert unknown.any()
    near_free = cv2.dilate(b.grid.free.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    assert not (near_free & unknown).any(), "a free cell touches the outside"
    occ = generate_building(5, furniture=False, outside="occupied")
    assert not occ.grid.unknown.any()
    assert np.array_equal(occ.grid.occupied, b.grid.occupied | unknown)


def test_bad_arguments_say_what_to_do() -> None:
    with pytest.raises(ValueError, match=r"unknown option.*hallway"):
        generate_building(1, hallway=True)
    with pytest.raises(ValueError, match="layout"):
        generate_building(1, layout="spiral")
    with pytest.raises(ValueError, match="resolution"):
        generate_building(1, resolution=0.0)
    with pytest.raises(ValueError, match="corridor_width"):
        generate_building(1, corridor_width=5.0)
    with pytest.raises(ValueError, match="seed"):
        generate_building(-1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tour_office_has_living_room_charger_and_bucket(seed: int) -> None:
    b = generate_tour_office(seed)
    living = [r for r in b.rooms if r.use == "living room"]
    assert len(living) == 1
    lid = living[0].id
    kinds_in_living = {f.kind for f in b.furniture if f.room == lid}
    assert {"couch", "tv", "table"} <= kinds_in_living
    corridor_ids = {c.id for c in b.corridors}
    chargers = [f for f in b.furniture if f.kind == "charging_station"]
    assert len(chargers) == 1 and chargers[0].room in corridor_ids
    buckets = [f for f in b.furniture if f.kind == "bucket"]
    assert len(buckets) == 1
    bx, by = buckets[0].center
    gaps = []
    for t in (f for f in b.furniture if f.kind == "table" and f.room == buckets[0].room):
        x0, y0, x1, y1 = _extent(t.center, t.size, t.yaw)
        gaps.append(math.hypot(max(x0 - bx, 0, bx - x1), max(y0 - by, 0, by - y1)))
    assert gaps and min(gaps) <= 0.7
    # solid items show in the grid where they stand
    for f in (*chargers, *buckets, *(f for f in b.furniture if f.kind in ("couch", "tv"))):
        r, c = b.grid.world_to_cell(np.array(f.center))
        assert b.grid.occupied[r, c], f


def _extent(
    center: tuple[float, float], size: tuple[float, float], yaw: float
) -> tuple[float, float, float, float]:
    w, d = size
    hx, hy = (w / 2, d / 2) if abs(math.cos(yaw)) > 0.5 else (d / 2, w / 2)
    return (center[0] - hx, center[1] - hy, center[0] + hx, center[1] + hy)


def test_label_picture_shows_labels_and_doors() -> None:
    b = generate_tour_office(3)
    img = label_building_png(b, annotate=True, scale=2)
    assert img.shape == (2 * b.grid.shape[0], 2 * b.grid.shape[1], 3) and img.dtype == np.uint8
    assert (img == (20, 20, 140)).all(axis=2).any(), "door bars drawn"
    plain = label_building_png(b, furniture_outlines=False)
    assert plain.shape == (*b.grid.shape, 3)


# ---------------------------------------------------------------------- realism
def _fractions(labels: np.ndarray) -> np.ndarray:
    """Fractions of labelled cells that are room, corridor (hallways included) and doorway."""
    n = (labels > 0).sum()
    return np.array(
        [
            (labels == ROOM).sum(),
            ((labels == CORRIDOR) | (labels == HALLWAY)).sum(),
            (labels == DOORWAY).sum(),
        ]
    ) / max(n, 1)


def _doorway_boxes(labels: np.ndarray) -> np.ndarray:
    """(short, long) bounding-box sides (cells) of each 8-connected doorway blob."""
    _, _, stats, _ = cv2.connectedComponentsWithStats((labels == DOORWAY).astype(np.uint8), connectivity=8)
    return np.sort(stats[1:, 2:4], axis=1)


def test_class_fractions_and_doorways_resemble_the_real_labelled_maps(
    shared_data: Path, furnished: list[Building]
) -> None:
    real_dir = shared_data / "ipa" / "labeled"
    real = {
        p.name.split(".")[0]: read_label_image(p, IPA_CODES) for p in sorted(real_dir.glob("*.labels.png"))
    }
    assert real, f"no labelled maps in {real_dir}"
    rf = np.array([_fractions(lab) for lab in real.values()])
    gen = [*furnished, *(generate_building(s) for s in range(30, 42))]
    gf = np.array([_fractions(b.labels) for b in gen])
    names = ("room", "corridor+hallway", "doorway")
    print("\nclass fractions of labelled cells (room, corridor+hallway, doorway):")
    for name, f in zip(real, rf, strict=True):
        print(f"  real {name:18s} {f.round(3)}")
    print(f"  real  min {rf.min(0).round(3)} mean {rf.mean(0).round(3)} max {rf.max(0).round(3)}")
    print(
        f"  generated ({len(gen)}) min {gf.min(0).round(3)} mean {gf.mean(0).round(3)} max {gf.max(0).round(3)}"
    )
    for k, name in enumerate(names):
        lo, hi = 0.7 * rf[:, k].min(), min(1.3 * rf[:, k].max(), 1.0)
        assert lo <= gf[:, k].mean() <= hi, (name, gf[:, k].mean(), lo, hi)
        # no generated building is wildly off either
        assert 0.4 * rf[:, k].min() <= np.median(gf[:, k]) and gf[:, k].max() <= min(
            2.0 * rf[:, k].max(), 1.0
        )
    # doorway rectangles: about as deep and as wide as the annotators painted them
    rb = np.concatenate([_doorway_boxes(lab) for lab in real.values()])
    gb = np.concatenate([_doorway_boxes(b.labels) for b in gen])
    rmed, gmed = np.median(rb, axis=0), np.median(gb, axis=0)
    print(f"doorway blob (short, long) side median, cells: real {rmed}, generated {gmed}")
    assert np.all(np.abs(gmed - rmed) <= 0.3 * rmed)
