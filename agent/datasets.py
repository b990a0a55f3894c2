"""Where the real data lives: ``$LOCI_DATA``, else ``../shared/data`` beside the clone.

The labelled maps, the legs scans, the real logs and the people benchmark the evaluations,
benchmarks and data tests read (its README says what each folder holds). Never copied into
the repository.
"""

from __future__ import annotations

import os
from pathlib import Path

#: The repository's root (the folder of ``pyproject.toml``).
REPO = Path(__file__).resolve().parents[1]
#: The environment variable that names the data folder.
DATA_ENV = "LOCI_DATA"


def data_dir() -> Path:
    """``$LOCI_DATA``, else ``../shared/data`` beside the repository."""
    env = os.environ.get(DATA_ENV)
    return Path(env) if env else REPO.parent / "shared" / "data"
