"""Domain randomisation: scaled, cluttered and shut-door map variants, real-looking scans."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from knowledge.places.dataset import LabelledMap
from knowledge.places.randomize import (
    ClutterParams,
    ScanNoiseParams,
    add_clutter,
    close_doors,
    perturb_scans,
    randomize_map,
    rescale,
)
from sim.buildings import generate_building

NOTHING = ScanNoiseParams(noise_std=0.0, quantum=0.0, no_echo_runs=0.0, legs=0.0)


@pytest.fixture(scope="module")
def office() -> LabelledMap:
    b = generate_building(11, layout="straight", hall=False, furniture=False)
    return LabelledMap(b.grid, b.labels)


def test_rescale_changes_only_the_cell_size(office: LabelledMap) -> None:
    big = rescale(office, 1.25)
    assert big.grid.resolution == pytest.approx(office.grid.resolution * 1.25)
    np.testing.assert_array_equal(big.labels, office.labels)
    np.testing.assert_array_equal(big.grid.state, office.grid.state)
    with pytest.raises(ValueError, match="positive"):
        rescale(office, 0.0)


def test_clutter_goes_into_rooms_and_keeps_doors_clear(office: LabelledMap) -> None:
    params = ClutterParams(wall=0.5, free=0.2, small=0.3, corridor=0.05)
    a = add_clutter(office, np.random.default_rng(4), params)
    b = add_clutter(office, np.random.default_rng(4), params)
    np.testing.assert_array_equal(a.grid.state, b.grid.state)  # a seed gives the same map
    added = a.grid.occupied & office.grid.free
    assert added.sum() > 500
    # only free room and corridor cells, never near a doorway, and they lose their labels
    labels_there = office.labels[added]
    assert set(np.unique(labels_there).tolist()) <= {1, 2}
    door = office.labels == 3
    keep = ndimage.binary_dilation(door, np.ones((3, 3), bool), iterations=round(0.6 / 0.05))
    assert not (added & keep).any()
    assert (a.labels[added] == 0).all()
    # most of it in rooms
    assert (labels_there == 1).mean() > 0.8
    # no densities: no change
    none = add_clutter(office, np.random.default_rng(4), ClutterParams(0, 0, 0, 0))
    np.testing.assert_array_equal(none.grid.state, office.grid.state)
    with pytest.raises(ValueError, match="legs_share"):
        ClutterParams(legs_share=2.0)


def test_shut_doors_cut_rooms_off(office: LabelledMap) -> None:
    eight = np.ones((3, 3), bool)
    _, before = ndimage.label(office.grid.free, eight)
    shut = close_doors(office, np.random.default_rng(0), 1.0)
    _, after = ndimage.label(shut.grid.free, eight)
    n_doors = ndimage.label(office.labels == 3, eight)[1]
    assert after > before + n_doors // 2  # most rooms are now closed off
    assert close_doors(office, np.random.default_rng(0), 0.0) is office
    with pytest.raises(ValueError, match="share"):
        close_doors(office, np.random.default_rng(0), 1.5)


def test_randomized_variants_differ_by_seed_and_stay_in_the_scale_range(office: LabelledMap) -> None:
    scales = []
    for seed in range(6):
        v = randomize_map(office, np.random.default_rng(seed), scale=(0.8, 1.25))
        k = v.grid.resolution / office.grid.resolution
        assert 0.8 - 1e-9 <= k <= 1.25 + 1e-9
        assert v.name.startswith(office.name + "~")
        scales.append(k)
    assert len(set(np.round(scales, 6))) == 6


def test_perturbed_scans_look_like_a_sick(rng: np.random.Generator) -> None:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 361)
    ranges = np.full((50, 361), 3.0)
    ranges[:, :20] = 30.0  # no hit there
    out = perturb_scans(ranges, angles, rng, max_range=30.0, params=ScanNoiseParams(legs=0.0))
    assert out.shape == ranges.shape and out.dtype == np.float32
    echo = out < 30.0
    # centimetre steps on beams with an echo, noise of about 1.5 cm
    np.testing.assert_allclose(out[echo] * 100, np.round(out[echo] * 100), atol=1e-3)
    assert 0.005 < np.std(out[echo] - 3.0) < 0.03
    # runs of no-echo beams where the wall was: about 1.7 per scan
    lost = (out >= 30.0) & (ranges < 30.0)
    assert 0.5 < lost.any(axis=1).mean() < 1.0
    # nothing asked, nothing done
    np.testing.assert_array_equal(perturb_scans(ranges, angles, rng, max_range=30.0, params=NOTHING), ranges)


def test_legs_only_shorten_beams_where_a_person_stands(rng: np.random.Generator) -> None:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 361)
    ranges = np.full((200, 361), 8.0)
    params = ScanNoiseParams(noise_std=0.0, quantum=0.0, no_echo_runs=0.0, legs=1.0, legs_range=(1.0, 3.0))
    out = perturb_scans(ranges, angles, rng, max_range=30.0, params=params)
    assert (out <= ranges + 1e-6).all()
    changed = out < ranges - 1e-6
    assert changed.any(axis=1).mean() > 0.95
    assert (out[changed] > 1.0 - 0.1).all() and (out[changed] < 3.0 + 0.1).all()
    # a leg at 1-3 m with a 5-8 cm radius covers a few beams at 0.5°, two legs ten at most
    assert 2 <= np.median(changed.sum(axis=1)) <= 20
