"""The conceptual map (book Sect. 7.2.4): an OWL ontology of places and objects, and a reasoner.

:class:`ConceptualMap` keeps acquired (robot), asserted (people) and inferred (HermiT)
knowledge about the areas of a building apart, on top of the innate commonsense ontology in
``ontology/loci-commonsense.owl``. See docs/conceptual.md.
"""

from knowledge.conceptual.errors import InconsistentKnowledge, JavaNotFound, ReasonerError, UnknownWord
from knowledge.conceptual.java import find_java
from knowledge.conceptual.lexicon import Lexicon, normalise
from knowledge.conceptual.map import AREA_CLASSES, Assertion, ConceptualMap, Contradiction
from knowledge.conceptual.resolve import Resolution, resolve_words
from knowledge.conceptual.world import default_ontology_path

__all__ = [
    "AREA_CLASSES",
    "Assertion",
    "ConceptualMap",
    "Contradiction",
    "InconsistentKnowledge",
    "JavaNotFound",
    "Lexicon",
    "ReasonerError",
    "Resolution",
    "UnknownWord",
    "default_ontology_path",
    "find_java",
    "normalise",
    "resolve_words",
]
