"""Reference resolution over a conceptual-map snapshot: what do people's words refer to?

"television" → the object kind Television and the television(s) seen; "kitchen" → the areas
of type Kitchen or named "kitchen"; "Anna's office" → the area so named; "the room with the
couch" → the rooms holding a couch. Works on the snapshot dict alone (plus the lexicon), so
an agent can answer from its cached state without touching the reasoner.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from knowledge.conceptual.lexicon import Lexicon, normalise

_WITH = re.compile(r"^(?P<head>.+?) (?:with|that has|which has|containing) (?P<tail>.+)$")


@dataclass(frozen=True)
class Resolution:
    """What some words refer to.

    ``kind``: "area" (``areas`` are the candidates), "object" (``objects`` are the instances
    and ``areas`` where they are) or "unknown". ``cls``: the ontology class the words name,
    if any. Several ``areas`` mean the words are ambiguous (or several places fit).
    """

    words: str
    kind: Literal["area", "object", "unknown"]
    cls: str | None = None
    areas: tuple[int, ...] = ()
    objects: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "words": self.words,
            "kind": self.kind,
            "class": self.cls,
            "areas": list(self.areas),
            "objects": list(self.objects),
        }


def _objects_matching(snapshot: Mapping[str, Any], lexicon: Lexicon, w: str) -> tuple[str | None, list[str]]:
    """Objects named ``w``, else objects whose kind is the class ``w`` names (or a subclass)."""
    objects: Mapping[str, Mapping[str, Any]] = snapshot.get("objects", {})
    named = [n for n in objects if normalise(n) == w]
    if named:
        return objects[named[0]].get("kind"), named
    info = lexicon.lookup(w)
    if info is None or info.is_area:
        return None, []
    return info.name, [n for n, o in objects.items() if o.get("kind") and lexicon.is_a(o["kind"], info.name)]


def _areas_matching(snapshot: Mapping[str, Any], lexicon: Lexicon, w: str) -> tuple[str | None, list[int]]:
    """Areas named ``w`` or typed by the class ``w`` names."""
    info = lexicon.lookup(w)
    cls = info.name if info is not None and info.is_area else None
    out: list[int] = []
    for area in snapshot.get("areas", {}).values():
        names = {normalise(n) for n in area.get("names", ())}
        types = set(area.get("types", ()))
        if area.get("class"):
            types.add(lexicon.classes[c].name if (c := area["class"].capitalize()) in lexicon.classes else c)
        if w in names or (cls is not None and (cls in types or (cls == "Area"))):
            out.append(int(area["id"]))
    return cls, sorted(out)


def resolve_words(snapshot: Mapping[str, Any], lexicon: Lexicon, words: str) -> Resolution:
    """Resolve ``words`` against ``snapshot`` (a :meth:`ConceptualMap.snapshot`)."""
    w = normalise(words)
    if not w:
        return Resolution(words, "unknown")
    m = _WITH.match(w)
    if m:
        head, tail = normalise(m["head"]), normalise(m["tail"])
        head_cls, head_areas = _areas_matching(snapshot, lexicon, head)
        kind, objs = _objects_matching(snapshot, lexicon, tail)
        if head_areas or head_cls is not None:
            objects = snapshot.get("objects", {})
            holding = {objects[n]["area"] for n in objs if objects[n].get("area") is not None}
            fits = tuple(a for a in head_areas if a in holding)
            return Resolution(
                words, "area", head_cls, fits, tuple(n for n in objs if objects[n].get("area") in fits)
            )
    kind, objs = _objects_matching(snapshot, lexicon, w)
    cls, areas = _areas_matching(snapshot, lexicon, w)
    if areas or cls is not None:
        return Resolution(words, "area", cls, tuple(areas))
    if kind is not None or objs:
        objects = snapshot.get("objects", {})
        where = sorted({objects[n]["area"] for n in objs if objects[n].get("area") is not None})
        return Resolution(words, "object", kind, tuple(where), tuple(sorted(objs)))
    return Resolution(words, "unknown")
