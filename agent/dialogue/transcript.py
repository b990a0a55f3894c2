"""The dialogue's transcript: who said what, when, one line per entry.

A transcript is a log written as the dialogue goes, so it is appended line by line and
flushed after every line (a killed process leaves every line it wrote); it is not rewritten
atomically like the project's other files. Two formats, chosen by the file name:

- ``*.jsonl`` / ``*.json``: one JSON object a line, ``{"stamp": 1717.2, "time":
  "2024-06-01T10:00:00.123+00:00", "speaker": "tutor", "kind": "utterance", "text": "...",
  ...}`` plus the entry's extra fields (``intent``, ``id``, ``in_reply_to``, ``status``).
- anything else: plain text, ``2024-06-01 10:00:00.123  tutor: Where are you?`` and
  ``[kind]`` for entries other than utterances and speech.

Speakers: the person (``tutor`` or the name a recogniser gave), ``robot`` for what the robot
says or asks, ``dialogue`` for the dialogue process's own notes (intents sent, timeouts).
"""

from __future__ import annotations

import datetime as dt
import json
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

#: The speaker name of the robot's lines and of the dialogue process's notes.
ROBOT = "robot"
DIALOGUE = "dialogue"


@dataclass(frozen=True)
class Entry:
    """One line of a transcript.

    Attributes:
        stamp: seconds since the Unix epoch.
        speaker: who speaks (see the module docstring).
        kind: ``utterance`` (a person), ``say`` / ``ask`` (the robot), ``sorry`` (not
            understood), ``intent`` (sent to the agent), ``timeout``, ``error``, ``late``.
        text: the words.
        extra: further fields (intent id, kind, status, ...).
    """

    stamp: float
    speaker: str
    kind: str
    text: str
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        when = dt.datetime.fromtimestamp(self.stamp, dt.UTC).isoformat(timespec="milliseconds")
        return {
            "stamp": round(self.stamp, 3),
            "time": when,
            "speaker": self.speaker,
            "kind": self.kind,
            "text": self.text,
            **self.extra,
        }

    def to_text(self) -> str:
        when = dt.datetime.fromtimestamp(self.stamp).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]
        tag = "" if self.kind in ("utterance", "say", "ask", "sorry") else f"[{self.kind}] "
        return f"{when}  {self.speaker}: {tag}{self.text}"


class Transcript:
    """Collects entries in memory (the last ``keep``) and appends them to a file if one is given.

    Args:
        path: the transcript file (created with its folder, appended to if it exists); None:
            memory only.
        keep: how many entries :attr:`entries` keeps.
    """

    def __init__(self, path: str | Path | None = None, *, keep: int = 1000) -> None:
        self.path = Path(path) if path is not None else None
        self.json = self.path is not None and self.path.suffix.lower() in (".jsonl", ".json")
        self.entries: deque[Entry] = deque(maxlen=keep)
        self._file: IO[str] | None = None
        if self.path is not None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._file = self.path.open("a", encoding="utf-8")
            except OSError as exc:
                raise OSError(
                    f"cannot write the transcript {self.path}: {exc}; choose another --transcript"
                ) from exc

    def add(self, speaker: str, kind: str, text: str, *, stamp: float | None = None, **extra: Any) -> Entry:
        """Record one entry (and append it to the file)."""
        entry = Entry(time.time() if stamp is None else stamp, speaker, kind, text, extra)
        self.entries.append(entry)
        if self._file is not None:
            line = json.dumps(entry.to_json(), ensure_ascii=False) if self.json else entry.to_text()
            self._file.write(line + "\n")
            self._file.flush()
        return entry

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> Transcript:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_transcript(path: str | Path) -> list[dict[str, Any]]:
    """The entries of a JSONL transcript (for tests and tools); lines that are not JSON are skipped."""
    out: list[dict[str, Any]] = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        try:
            doc = json.loads(line)
        except ValueError:
            continue
        if isinstance(doc, dict):
            out.append(doc)
    return out
