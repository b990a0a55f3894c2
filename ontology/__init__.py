"""The innate knowledge: the commonsense OWL ontology files (RDF/XML, open them in Protégé).

A package only so that the ``.owl`` files are installed with the code (package data);
``knowledge.conceptual`` finds them next to ``knowledge/`` in the source tree and in an
installed environment alike. See README.md in this folder.
"""
