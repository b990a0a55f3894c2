"""State on request: queryables that answer from the agent's current state, and ``get``.

Late subscribers get no history in Zenoh, so the graph, the areas and the current place are
also served by queryables under ``loci/<robot>/state/<name>``. A :class:`StateQueryable`
answers every query from a callable returning the current state (a JSON message dict, its
encoded bytes, or None for "no state yet"). The callable runs on Zenoh's callback thread:
it must be thread-safe and quick. :class:`StateCell` is such a source: the event loop
``set()`` s a new state (validated and encoded once, in the loop), the queryable reads the
latest bytes. A cell without a state answers with an error whose reason is the cell's
``pending`` (``"no state yet"``, or while the agent starts ``"starting: ..."``): an agent
still loading its saved map never answers with an empty one.

Every query is finished (``with query:``) on every path, errors included, so a caller's
``get()`` returns as soon as the replies are in instead of waiting for its timeout.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import zenoh

from agent.bus.codecs import JSON_ENCODING
from agent.bus.schemas import SCHEMAS, SchemaRegistry
from knowledge.errors import ProtocolError

log = logging.getLogger(__name__)

StateSource = Callable[[], Mapping[str, Any] | bytes | None]
#: the error reason of a query for a state not there yet
NO_STATE = "no state yet"


class StateCell:
    """The latest state of one kind, shared by the event loop (writer) and Zenoh's threads.

    Args:
        schema_id: every state set here must validate as this schema (e.g. ``loci.graph/1``).
        pending: the error reason a query gets while the cell has no state.
    """

    def __init__(
        self, schema_id: str, registry: SchemaRegistry = SCHEMAS, *, pending: str = NO_STATE
    ) -> None:
        registry.get(schema_id)
        self.schema_id = schema_id
        self._registry = registry
        self._lock = threading.Lock()
        self._data: bytes | None = None
        #: why there is no state (the error reason of a query while there is none)
        self.pending = pending

    def set(self, message: Mapping[str, Any]) -> None:
        """Validate, encode and store a new state (raises :class:`ProtocolError` if invalid)."""
        data = self._registry.encode(message, self.schema_id)
        with self._lock:
            self._data = data

    def clear(self) -> None:
        with self._lock:
            self._data = None

    def __call__(self) -> bytes | None:
        with self._lock:
            return self._data


def _error(reason: str, key: str) -> bytes:
    return SCHEMAS.encode({"schema": "loci.error/1", "reason": reason, "key": key, "stamp": time.time()})


class StateQueryable:
    """Serve ``key`` from ``source``; closed with :meth:`close` (or the session).

    Replies carry the JSON state with encoding ``application/json;<schema_id>``; a dict from
    the source is validated against ``schema_id`` and encoded, bytes are sent as they are
    (a :class:`StateCell` validated them already). When the source returns None the reply is
    an error ``loci.error/1`` "no state yet" (a cell's ``pending`` reason); when it raises,
    an error with the reason (and the exception is logged). ``schema_id`` defaults to a
    :class:`StateCell` source's.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        source: StateSource,
        schema_id: str | None = None,
        registry: SchemaRegistry = SCHEMAS,
    ) -> None:
        if schema_id is None:
            if not isinstance(source, StateCell):
                raise ValueError(
                    "StateQueryable needs schema_id (e.g. 'loci.graph/1') unless the source is a StateCell"
                )
            schema_id = source.schema_id
        registry.get(schema_id)
        self.key = key
        self.schema_id = schema_id
        self._source = source
        self._registry = registry
        self._encoding = f"{JSON_ENCODING};{schema_id}"
        self.queries = 0
        self._queryable = session.declare_queryable(key, self._on_query, complete=True)

    def _on_query(self, query: zenoh.Query) -> None:
        with query:
            self.queries += 1
            try:
                state = self._source()
                if state is None:
                    reason = str(getattr(self._source, "pending", NO_STATE))
                    query.reply_err(_error(reason, self.key), encoding=f"{JSON_ENCODING};loci.error/1")
                    return
                data = state if isinstance(state, bytes) else self._registry.encode(state, self.schema_id)
                query.reply(self.key, data, encoding=self._encoding)
            except Exception as exc:
                log.exception("%s: answering a query failed", self.key)
                query.reply_err(
                    _error(f"{type(exc).__name__}: {exc}", self.key), encoding=f"{JSON_ENCODING};loci.error/1"
                )

    def close(self) -> None:
        with contextlib.suppress(zenoh.ZError):
            self._queryable.undeclare()

    def __enter__(self) -> StateQueryable:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class StateReply:
    """One answer to :func:`query_state`: the state, or the error the queryable gave."""

    key: str
    value: dict[str, Any] | None
    error: str | None = None


def query_state(
    session: zenoh.Session, selector: str, timeout: float = 2.0, registry: SchemaRegistry = SCHEMAS
) -> list[StateReply]:
    """Ask the queryables matching ``selector`` (e.g. ``loci/rosie/state/**``); blocks.

    Returns one :class:`StateReply` per answer (validated; an answer that does not validate
    becomes an error reply). Returns ``[]`` when nobody answers within ``timeout`` seconds.
    From the event loop, call it with ``asyncio.to_thread``.
    """
    out: list[StateReply] = []
    for reply in session.get(selector, timeout=timeout):
        sample = reply.ok
        if sample is not None:
            key = str(sample.key_expr)
            try:
                out.append(StateReply(key, registry.decode(sample.payload.to_bytes())))
            except ProtocolError as exc:
                out.append(StateReply(key, None, f"invalid reply: {exc}"))
            continue
        err = reply.err
        if err is None:
            continue
        try:
            reason = str(registry.decode(err.payload.to_bytes(), "loci.error/1")["reason"])
            out.append(StateReply(selector, None, reason))
        except ProtocolError:
            out.append(StateReply(selector, None, f"error reply: {err.payload.to_bytes()[:200]!r}"))
    return out
