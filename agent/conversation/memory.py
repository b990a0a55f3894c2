"""The concepts the dialogue needs, kept in memory without reasoning (no Java).

:class:`MemoryConcepts` stands in for the conceptual service (:mod:`agent.conceptual_service`)
when ``[conceptual]`` is off: what was said and seen is kept, nothing is inferred. It offers the
service's interface (:class:`agent.conversation.agent.Concepts`) and the part of
``knowledge.conceptual.ConceptualMap`` the dialogue calls.
"""

from __future__ import annotations

import asyncio
import re
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any, TypeVar

from knowledge.topology.areas import AreaClassChanged, AreaCreated, AreaEvent, AreaRemoved, AreasMerged

__all__ = ["AREA_CLASSES", "MemoryConcepts", "class_of_words"]

T = TypeVar("T")

#: Classes an AREA's ``class`` may take (others, e.g. "doorway", are None).
AREA_CLASSES = ("room", "corridor", "hallway")


def class_of_words(words: str) -> str:
    """Words as an ontology-like class name: "charging station" → "ChargingStation"."""
    return "".join(w[:1].upper() + w[1:] for w in re.split(r"[\s_\-]+", words.strip()) if w)


class MemoryConcepts:
    """The concepts the dialogue needs, kept in memory without reasoning (no Java).

    It offers both :class:`Concepts` (``submit`` runs the function at once) and the part of
    ``knowledge.conceptual.ConceptualMap`` the dialogue calls (``set_area``, ``merge_areas``,
    ``add_object``, ``assert_type``, ``assert_name``...). An asserted type becomes the
    area's only type ("kitchen" → ``["Kitchen"]``); nothing is inferred.
    """

    def __init__(self) -> None:
        self.areas: dict[int, dict[str, Any]] = {}
        self.objects: dict[str, dict[str, Any]] = {}
        self.version = 0

    # ---- the service's side
    def snapshot(self) -> dict[str, Any]:
        areas: dict[str, Any] = {}
        for aid, a in sorted(self.areas.items()):
            objs = [
                {"name": o["name"], "kind": o["kind"]}
                for o in sorted(self.objects.values(), key=lambda o: o["name"])
                if o["area"] == aid
            ]
            types = [a["type"]] if a.get("type") else []
            areas[str(aid)] = {
                "id": aid,
                "class": a.get("class"),
                "types": types,
                "names": list(a.get("names", [])),
                "objects": objs,
                "asserted": {"types": dict(a.get("asserted_types", {})), "names": dict(a.get("by", {}))},
                "inferred": [],
            }
        return {
            "areas": areas,
            "objects": {k: dict(v) for k, v in sorted(self.objects.items())},
            "version": self.version,
        }

    def submit(self, fn: Callable[[Any], T]) -> Awaitable[T]:
        fut: asyncio.Future[T] = asyncio.get_running_loop().create_future()
        try:
            fut.set_result(fn(self))
        except Exception as exc:
            fut.set_exception(exc)
        return fut

    def request_reasoning(self) -> None:
        return None

    def apply_area_events(self, events: Sequence[AreaEvent], labels: Mapping[int, str | None]) -> None:
        for e in events:
            if isinstance(e, AreasMerged):
                for gone in e.absorbed:
                    self.merge_areas(e.area_id, gone)
            elif isinstance(e, AreaCreated):
                self.set_area(e.area_id, labels.get(e.area_id, e.label))
            elif isinstance(e, AreaClassChanged):
                self.set_area(e.area_id, e.new)
            elif isinstance(e, AreaRemoved) and e.cause != "merged":
                self.remove_area(e.area_id)

    # ---- the map's side
    def _area(self, area: int) -> dict[str, Any]:
        return self.areas.setdefault(int(area), {"class": None, "names": []})

    def set_area(self, area: int, cls: str | None) -> None:
        self._area(area)["class"] = cls if cls in AREA_CLASSES else None
        self.version += 1

    def remove_area(self, area: int) -> None:
        self.areas.pop(int(area), None)
        for name in [n for n, o in self.objects.items() if o["area"] == area]:
            del self.objects[name]
        self.version += 1

    def merge_areas(self, keep: int, gone: int) -> None:
        a, b = self._area(keep), self.areas.pop(int(gone), {})
        for n in b.get("names", []):
            if n not in a["names"]:
                a["names"].append(n)
        if not a.get("type") and b.get("type"):
            a["type"] = b["type"]
        for o in self.objects.values():
            if o["area"] == gone:
                o["area"] = keep
        self.version += 1

    def add_object(
        self, name: str, kind: str, area: int, node: int | None, *, source: str = "camera"
    ) -> None:
        self._area(area)
        self.objects[name] = {"name": name, "kind": kind, "area": int(area), "node": node, "source": source}
        self.version += 1

    def remove_object(self, name: str) -> None:
        self.objects.pop(name, None)
        self.version += 1

    def assert_type(self, area: int, word: str, speaker: str) -> None:
        a = self._area(area)
        w = " ".join(word.lower().split())
        if w in AREA_CLASSES:
            a["class"] = w
        else:
            a["type"] = class_of_words(w)
        a.setdefault("asserted_types", {})[speaker] = w
        self.version += 1

    def assert_name(self, area: int, name: str, speaker: str) -> None:
        a = self._area(area)
        n = " ".join(name.split())
        if n not in a["names"]:
            a["names"].append(n)
        a.setdefault("by", {}).setdefault(speaker, [])
        if n not in a["by"][speaker]:
            a["by"][speaker].append(n)
        self.version += 1
