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
