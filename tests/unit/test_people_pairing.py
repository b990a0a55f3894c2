"""Legs → people."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.people.pairing import pair_legs


def test_two_legs_30_cm_apart_are_one_person_at_their_midpoint() -> None:
    people = pair_legs([[2.0, 0.15], [2.0, -0.15]])
    assert len(people) == 1
    np.testing.assert_allclose(people.positions[0], [2.0, 0.0])
    assert people.n_legs.tolist() == [2]
    assert sorted(people.legs[0].tolist()) == [0, 1]


def test_lone_legs_are_people_by_default_and_can_be_dropped() -> None:
    legs = [[1.0, 0.0], [3.0, 0.0]]  # 2 m apart: two people, one leg each
    people = pair_legs(legs)
    assert len(people) == 2
    assert people.n_legs.tolist() == [1, 1]
    assert people.legs[:, 1].tolist() == [-1, -1]
    np.testing.assert_allclose(people.positions, legs)
    assert len(pair_legs(legs, lone_legs="drop")) == 0


def test_closest_legs_are_paired_first() -> None:
    # A–B 0.25 m, B–C 0.2 m, C–D 0.25 m: greedy pairs B–C, then A and D are 0.7 m apart (lone)
    legs = np.array([[0.0, 0.0], [0.25, 0.0], [0.45, 0.0], [0.7, 0.0]])
    people = pair_legs(legs, max_distance=0.6)
    assert len(people) == 3
    pairs = [sorted(p) for p in people.legs.tolist() if p[1] >= 0]
    assert pairs == [[1, 2]]
    # two people side by side, each with legs 0.2 m apart, 1 m between them
    legs2 = np.array([[2.0, 0.1], [2.0, -0.1], [2.0, 1.1], [2.0, 0.9]])
    people2 = pair_legs(legs2)
    assert len(people2) == 2 and people2.n_legs.tolist() == [2, 2]
    np.testing.assert_allclose(sorted(people2.positions[:, 1].tolist()), [0.0, 1.0])


def test_no_legs_no_people() -> None:
    people = pair_legs(np.zeros((0, 2)))
    assert len(people) == 0 and people.positions.shape == (0, 2)
    assert len(pair_legs([])) == 0


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="max_distance"):
        pair_legs([[0.0, 0.0]], max_distance=0.0)
    with pytest.raises(ValueError, match="lone_legs"):
        pair_legs([[0.0, 0.0]], lone_legs="maybe")
