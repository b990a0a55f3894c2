"""The owlready2 side of the conceptual map: loading ontologies, raw triples per layer, the lexicon.

The map's facts are plain triples in three ontologies of one owlready2 world (*acquired*,
*asserted*, *inferred*), written with the ontologies' raw triple functions so that each triple
lands in the layer we name and nothing else changes: owlready2's entity API would put an
individual's new types in the individual's home ontology and re-parent cached Python objects
after reasoning, mixing the layers. Only the innate classes are used as Python objects (read only).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import owlready2  # type: ignore[import-untyped]

from knowledge.conceptual.errors import UnknownWord
from knowledge.conceptual.lexicon import ClassInfo, Lexicon, class_words, normalise
from knowledge.errors import ConfigError

COMMONSENSE_IRI = "http://genius-loci.org/ontology/commonsense.owl"
CS = COMMONSENSE_IRI + "#"
SKOS_ALT = "http://www.w3.org/2004/02/skos/core#altLabel"
RDF_TYPE: int = owlready2.rdf_type
NAMED_INDIVIDUAL: int = owlready2.owl_named_individual
RDFS_LABEL: int = owlready2.label.storid
PLAIN: int = 60  # owlready2's datatype code of a plain string literal
INTEGER: int = 43  # ... of an integer literal


def default_ontology_path() -> Path:
    """The bundled commonsense ontology (``ontology/loci-commonsense.owl`` of the source tree)."""
    return Path(__file__).resolve().parents[2] / "ontology" / "loci-commonsense.owl"


def local_name(iri: str) -> str:
    """The part of an IRI after ``#`` (or the last ``/``)."""
    return iri.rsplit("#", 1)[-1] if "#" in iri else iri.rstrip("/").rsplit("/", 1)[-1]


def load_ontology(world: Any, path: Path) -> Any:
    """Load an OWL file into ``world`` (again if the file changed since it was stored there)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"ontology file {p} does not exist: fix [conceptual] ontologies in the config")
    try:
        return world.get_ontology(p.resolve().as_uri()).load(reload_if_newer=True)
    except Exception as e:  # owlready2 raises bare exceptions on parse errors
        raise ConfigError(f"cannot load the ontology {p}: {e}") from e


class Layer:
    """Raw triples of one ontology (one layer of the map), by storid."""

    def __init__(self, onto: Any) -> None:
        self.onto = onto
        self.storid: int = onto.storid

    def objs(self, s: int | None, p: int | None) -> list[int]:
        return [o for (_, _, o) in self.onto._get_obj_triples_spo_spo(s, p, None)]

    def subjects(self, p: int, o: int) -> list[int]:
        return [s for (s, _, _) in self.onto._get_obj_triples_spo_spo(None, p, o)]

    def datas(self, s: int, p: int) -> list[Any]:
        return [o for (_, _, o, _) in self.onto._get_data_triples_spod_spod(s, p, None, None)]

    def add(self, s: int, p: int, o: int) -> None:
        if not self.onto._has_obj_triple_spo(s, p, o):
            self.onto._add_obj_triple_raw_spo(s, p, o)

    def add_data(self, s: int, p: int, o: Any, d: int = PLAIN) -> None:
        self.onto._add_data_triple_raw_spod(s, p, o, d)

    def remove(self, s: int | None, p: int | None = None, o: int | None = None) -> None:
        self.onto._del_obj_triple_raw_spo(s, p, o)

    def remove_data(self, s: int, p: int | None = None) -> None:
        self.onto._del_data_triple_raw_spod(s, p, None, None)

    def set_data(self, s: int, p: int, o: Any, d: int = PLAIN) -> None:
        self.remove_data(s, p)
        self.add_data(s, p, o, d)

    def capture(self, s: int) -> tuple[list[tuple[int, int, int]], list[tuple[int, int, Any, Any]]]:
        """Every triple with subject ``s`` (objects, data), for an undo."""
        return (
            list(self.onto._get_obj_triples_spo_spo(s, None, None)),
            list(self.onto._get_data_triples_spod_spod(s, None, None, None)),
        )

    def restore(
        self, s: int, saved: tuple[list[tuple[int, int, int]], list[tuple[int, int, Any, Any]]]
    ) -> None:
        """Replace the triples of subject ``s`` by ``saved`` (from :meth:`capture`)."""
        self.remove(s)
        self.remove_data(s)
        for _, p, o in saved[0]:
            self.onto._add_obj_triple_raw_spo(s, p, o)
        for _, p, o, d in saved[1]:
            self.onto._add_data_triple_raw_spod(s, p, o, d)

    def clear(self) -> None:
        """Drop every triple of the layer except its ontology header."""
        header = self.capture(self.storid)
        self.onto._del_obj_triple_raw_spo(None, None, None)
        self.onto._del_data_triple_raw_spod(None, None, None, None)
        self.restore(self.storid, header)


def build_lexicon(world: Any, ontologies: Sequence[Any]) -> Lexicon:
    """The classes under ``Area`` and ``Object`` of the loaded ontologies, their words and disjointness."""
    area = world[CS + "Area"]
    thing = world[CS + "Object"]
    if area is None or thing is None:
        raise ConfigError("the commonsense ontology has no Area or Object class: is it the right file?")
    alt = world[SKOS_ALT]
    infos: list[ClassInfo] = []
    words: dict[str, str] = {}
    secondary: list[tuple[str, str]] = []
    for root, is_area in ((area, True), (thing, False)):
        for cls in sorted(root.descendants(), key=lambda c: c.iri):
            ancestors = frozenset(
                a.name
                for a in cls.ancestors()
                if a is not owlready2.Thing and isinstance(a, owlready2.ThingClass)
            )
            labels = [str(x) for x in cls.label]
            label = labels[0] if labels else class_words(cls.name)
            infos.append(ClassInfo(cls.name, cls.iri, label, is_area, ancestors))
            for w in labels:
                words.setdefault(normalise(w), cls.name)
            extra = [str(x) for x in alt[cls]] if alt is not None else []
            secondary.extend((normalise(w), cls.name) for w in [*extra, class_words(cls.name)])
    for w, name in secondary:  # synonyms never shadow a class's own label
        words.setdefault(w, name)
    disjoint: set[frozenset[str]] = set()
    for onto in ontologies:
        for axiom in onto.disjoint_classes():
            names = [e.name for e in axiom.entities if isinstance(e, owlready2.ThingClass)]
            disjoint.update(frozenset((a, b)) for i, a in enumerate(names) for b in names[i + 1 :])
    return Lexicon(infos, words, disjoint)


def class_of(lexicon: Lexicon, word: str, *, area: bool) -> ClassInfo:
    """The area class (``area=True``) or object kind a word or class name names; raises :class:`UnknownWord`."""
    info = lexicon.classes.get(word) or lexicon.lookup(word)
    what = "area type" if area else "object kind"
    if info is None:
        known = ", ".join(sorted(c.label for c in lexicon.classes.values() if c.is_area == area))
        raise UnknownWord(f"{word!r} is not a known {what} (known: {known})")
    if info.is_area != area:
        other = "object kind" if area else "area type"
        raise UnknownWord(f"{word!r} is an {other}, not an {what}")
    return info


def individuals(layers: Iterable[Layer], prefix: str, world: Any) -> dict[str, int]:
    """IRI → storid of the named individuals declared in ``layers`` whose IRI starts with ``prefix``."""
    out: dict[str, int] = {}
    for layer in layers:
        for s in layer.subjects(RDF_TYPE, NAMED_INDIVIDUAL):
            iri = world._unabbreviate(s)
            if iri.startswith(prefix):
                out[iri] = s
    return out
