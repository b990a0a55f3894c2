"""Shared fixtures: the real data folder (skipped cleanly when absent) and seeded RNGs."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
#: The third-party data beside the clone (never copied into the repository).
DATA = Path(os.environ.get("LOCI_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (or ``$LOCI_DATA``); the test is skipped when it is absent."""
    if not DATA.is_dir():
        pytest.skip(f"real data folder {DATA} is absent (set LOCI_DATA to point at it)")
    return DATA


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


#: The files that take minutes (whole guided tours beside a busy core), in the order they
#: should start. ``make test`` gives each of its two workers a file at a time
#: (``--dist loadfile --no-loadscope-reorder``): started last, the longest file ran alone
#: while the other worker idled; started first, the others fill the second worker beside it.
LONGEST_FIRST = ("e2e/test_demo_noisy.py", "e2e/test_demo_tour.py")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the longest files first, then the rest of tests/e2e, then everything else."""
    here = Path(__file__).resolve().parent

    def rank(item: pytest.Item) -> int:
        try:
            rel = item.path.resolve().relative_to(here).as_posix()
        except ValueError:
            return len(LONGEST_FIRST) + 1
        if rel in LONGEST_FIRST:
            return LONGEST_FIRST.index(rel)
        return len(LONGEST_FIRST) + (0 if rel.startswith("e2e/") else 1)

    items.sort(key=rank)  # stable: each file's tests keep their order
