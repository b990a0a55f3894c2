"""The protocol's bookkeeping in tools/evaluate_people_tracks.py: counts pooled over parts,
the selection rule, and the grid whose first candidate is the default."""

from __future__ import annotations

import pytest

from tools.evaluate_people_tracks import DETECTORS, GRID, candidates, pick, pooled


def scored(
    valid: int, switches: int, misses: int, fps: int, objects: int, motp: float, frames: int = 10
) -> dict:
    mota = 100.0 * (1 - (misses + fps + switches) / objects) if objects else None
    return {
        "clear_mot": {"valid": valid, "id_switches": switches, "misses": misses, "false_positives": fps,
                      "objects": objects, "mota_pct": mota, "motp_m": motp},
        "frames": frames,
    }  # fmt: skip


def test_pooled_adds_counts_and_recomputes_mota_and_motp_from_the_sums() -> None:
    a = scored(valid=8, switches=0, misses=2, fps=5, objects=10, motp=0.1)  # MOTA 30 %
    b = scored(valid=20, switches=2, misses=8, fps=0, objects=30, motp=0.2)  # MOTA 66.7 %
    p = pooled([a, b])
    m = p["clear_mot"]
    assert (m["valid"], m["id_switches"], m["misses"], m["false_positives"], m["objects"]) == (
        28,
        2,
        10,
        5,
        40,
    )
    assert m["mota_pct"] == pytest.approx(100 * (1 - 17 / 40))  # not the mean of 30 and 66.7
    assert m["motp_m"] == pytest.approx((8 * 0.1 + 22 * 0.2) / 30)  # weighted by the matches
    assert p["frames"] == 20
    assert pooled([scored(0, 0, 0, 0, 0, 0.0)])["clear_mot"]["mota_pct"] is None


def test_pick_takes_the_best_mota_then_fewest_false_positives_then_misses_then_the_first() -> None:
    best = scored(10, 0, 5, 5, 20, 0.1)  # 50 %
    worse = scored(12, 0, 3, 8, 20, 0.1)  # 45 %
    same_more_fp = scored(12, 0, 3, 7, 20, 0.1)  # 50 %, more false positives
    assert pick([("a", worse), ("b", best), ("c", same_more_fp)]) == 1
    tie_fewer_misses = scored(10, 0, 4, 6, 20, 0.1)  # 50 %, 6 false positives
    assert pick([("a", tie_fewer_misses), ("b", same_more_fp)]) == 0
    assert pick([("a", best), ("b", dict(best))]) == 0  # a full tie: the earlier one


def test_the_grid_starts_with_the_default_and_the_bundled_detector() -> None:
    c = candidates()
    assert len(c) == len({tuple(sorted(x.items())) for x in c}) == 3 * 3 * 3 * 2
    assert c[0] == {k: v[0] for k, v in GRID.items()}
    assert c[0] == {"min_score": 0.0, "min_seen_through": 3, "settle": 2.0, "min_travel": 0.0}
    assert DETECTORS[0][1] is None  # the bundled detector, never trained on the bag
