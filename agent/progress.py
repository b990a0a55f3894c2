"""Progress bars for long work, from the core's ``progress(stage, done, total)`` callbacks."""

from __future__ import annotations

import sys
from types import TracebackType
from typing import Any

from tqdm import tqdm


class Progress:
    """A ``progress(stage, done, total)`` callable that shows one tqdm bar per stage on stderr.

    Disabled (silent) when ``enabled`` is false, e.g. with ``--quiet``, and when standard
    error is not a terminal (a log file or a journal gets no bar redraws). Use as a context
    manager so the last bar is closed.
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self._bar: tqdm[Any] | None = None
        self._stage: str | None = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage != self._stage or self._bar is None:
            self.close()
            self._stage = stage
            self._bar = tqdm(
                total=total, desc=stage, unit="", leave=False, file=sys.stderr, dynamic_ncols=True
            )
        bar = self._bar
        if bar.total != total:
            bar.total = total
        bar.update(done - bar.n)
        if done >= total:
            self.close()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
            self._stage = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
