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

A :class:`RequestQueryable` does something on request (``loci/<robot>/map/save``): the
query's payload is a JSON request, validated on Zenoh's thread; a coroutine on the event
loop answers it, so Zenoh's thread never waits for the work. :func:`request` asks one.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Self

import zenoh

from agent.bus.codecs import JSON_ENCODING
from agent.bus.schemas import SCHEMAS, SchemaRegistry
from knowledge.errors import LociError, ProtocolError

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


#: seconds between the tries of :func:`request` while no queryable matches
RETRY = 0.1
#: the encoding of an error reply
ERROR_ENCODING = f"{JSON_ENCODING};loci.error/1"


def _error(reason: str, key: str) -> bytes:
    return SCHEMAS.encode({"schema": "loci.error/1", "reason": reason, "key": key, "stamp": time.time()})


class _Queryable:
    """A declared queryable on ``key``: closed with :meth:`close` (or the session), or as a
    context manager."""

    def __init__(self, session: zenoh.Session, key: str, reply_schema: str, registry: SchemaRegistry) -> None:
        """Declare the queryable (the subclass's state must be set: queries come at once)."""
        registry.get(reply_schema)
        self.key = key
        self._registry = registry
        self._encoding = f"{JSON_ENCODING};{reply_schema}"
        self.queries = 0
        self._queryable = session.declare_queryable(key, self._on_query, complete=True)

    def _on_query(self, query: zenoh.Query) -> None:
        raise NotImplementedError

    def _failed(self, query: zenoh.Query, exc: Exception, what: str) -> None:
        """Answer ``query`` with an unexpected failure: logged with its traceback, the reason
        names the exception."""
        log.exception("%s: %s failed", self.key, what)
        query.reply_err(_error(f"{type(exc).__name__}: {exc}", self.key), encoding=ERROR_ENCODING)

    def close(self) -> None:
        with contextlib.suppress(zenoh.ZError):
            self._queryable.undeclare()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class StateQueryable(_Queryable):
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
        self.schema_id = schema_id
        self._source = source
        super().__init__(session, key, schema_id, registry)

    def _on_query(self, query: zenoh.Query) -> None:
        with query:
            self.queries += 1
            try:
                state = self._source()
                if state is None:
                    reason = str(getattr(self._source, "pending", NO_STATE))
                    query.reply_err(_error(reason, self.key), encoding=ERROR_ENCODING)
                    return
                data = state if isinstance(state, bytes) else self._registry.encode(state, self.schema_id)
                query.reply(self.key, data, encoding=self._encoding)
            except Exception as exc:
                self._failed(query, exc, "answering a query")


Handler = Callable[[dict[str, Any]], Awaitable[Mapping[str, Any]]]


class RequestQueryable(_Queryable):
    """Serve requests on ``key``; closed with :meth:`close` (or the session).

    Each query's payload must be a ``request_schema`` message (a query without one, or one
    that does not validate, gets a ``loci.error/1`` reply saying so, at once). The request
    goes to ``handler``, a coroutine run on ``loop``; the message it returns is validated as
    ``reply_schema`` and sent. A handler that raises a :class:`~knowledge.errors.LociError`,
    ``ValueError`` or ``OSError`` is answered with its message as the reason (the request was
    refused: a bad folder, nothing to save yet); anything else also names the exception and is
    logged with its traceback. The query is finished once answered, on every path.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        handler: Handler,
        request_schema: str,
        reply_schema: str,
        loop: asyncio.AbstractEventLoop,
        registry: SchemaRegistry = SCHEMAS,
    ) -> None:
        registry.get(request_schema)
        self.request_schema = request_schema
        self.reply_schema = reply_schema
        self._handler = handler
        self._loop = loop
        super().__init__(session, key, reply_schema, registry)

    def _on_query(self, query: zenoh.Query) -> None:
        self.queries += 1
        payload = query.payload
        try:
            if payload is None:
                raise ProtocolError(
                    f"a query of {self.key} carries a {self.request_schema} request; this one has none"
                )
            message = self._registry.decode(payload.to_bytes(), self.request_schema)
        except ProtocolError as exc:
            with query:
                query.reply_err(_error(str(exc), self.key), encoding=ERROR_ENCODING)
            return
        answer = self._answer(query, message)
        try:
            asyncio.run_coroutine_threadsafe(answer, self._loop)
        except RuntimeError as exc:  # the loop is closed: the agent is stopping
            answer.close()
            with query:
                query.reply_err(
                    _error(f"{self.key} cannot answer now: {exc}", self.key), encoding=ERROR_ENCODING
                )

    async def _answer(self, query: zenoh.Query, message: dict[str, Any]) -> None:
        with query:
            try:
                data = self._registry.encode(await self._handler(message), self.reply_schema)
            except (LociError, ValueError, OSError) as exc:
                log.info("%s: refused: %s", self.key, exc)
                query.reply_err(_error(str(exc), self.key), encoding=ERROR_ENCODING)
                return
            except Exception as exc:
                self._failed(query, exc, "answering a request")
                return
            query.reply(self.key, data, encoding=self._encoding)


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
    return _replies(session.get(selector, timeout=timeout), selector, registry)


def request(
    session: zenoh.Session,
    key: str,
    message: Mapping[str, Any],
    schema_id: str,
    timeout: float = 10.0,
    registry: SchemaRegistry = SCHEMAS,
) -> list[StateReply]:
    """Send ``message`` (validated as ``schema_id``) to the :class:`RequestQueryable` on
    ``key`` and collect the answers as :func:`query_state` does (``[]``: nobody answered
    within ``timeout`` seconds); blocks.

    A query that no queryable matches ends at once, and a session just opened may not know
    the agent's queryable yet: such a query is sent again every :data:`RETRY` seconds until
    one is answered or the time is up (a queryable that matched always answers, so no
    request is done twice).
    """
    data = registry.encode(message, schema_id)
    deadline = time.monotonic() + timeout
    while True:
        left = max(deadline - time.monotonic(), 0.001)
        sent = session.get(key, timeout=left, payload=data, encoding=f"{JSON_ENCODING};{schema_id}")
        out = _replies(sent, key, registry)
        if out or time.monotonic() + RETRY >= deadline:
            return out
        time.sleep(RETRY)


def _replies(replies: Iterable[zenoh.Reply], selector: str, registry: SchemaRegistry) -> list[StateReply]:
    out: list[StateReply] = []
    for reply in replies:
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
