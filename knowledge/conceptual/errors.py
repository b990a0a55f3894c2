"""Errors of the conceptual map, children of the shared hierarchy in :mod:`knowledge.errors`."""

from __future__ import annotations

from knowledge.errors import ConfigError, LociError


class JavaNotFound(ConfigError):
    """No usable Java runtime for the HermiT reasoner (names how to get one)."""


class ReasonerError(LociError, RuntimeError):
    """HermiT failed for another reason than an inconsistency (crash, timeout, bad input)."""


class InconsistentKnowledge(LociError, ValueError):
    """The reasoner found the map inconsistent; the offending changes were rolled back.

    ``rolled_back`` lists the changes undone (plain descriptions such as
    ``"assert_type(3, 'kitchen', 'anna')"``), newest last.
    """

    def __init__(self, message: str, rolled_back: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.rolled_back = rolled_back


class UnknownWord(LociError, ValueError):
    """A word that names no class of the ontology (or a class of the wrong kind)."""
