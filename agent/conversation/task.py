"""The dialogue's bus task: intents and base statuses in, :class:`~agent.conversation.agent.DialogueAgent`'s
messages out, and its :meth:`~agent.conversation.agent.DialogueAgent.tick` every ``period`` seconds.

Started by :mod:`agent.runtime`; everything it does with a message is the agent's (this
module only moves payloads and keeps serving when one is bad). An intent that makes the
decoder or the agent fail unexpectedly is answered with an error (when it has an id),
counted as invalid and logged once in full, then as counts; the next intent is served.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable
from typing import Any

from agent.bus.bridge import BusClosed
from agent.conversation.agent import DialogueAgent, Outgoing
from agent.ratelog import RateLimitedLog
from knowledge.errors import ProtocolError

__all__ = ["run_dialogue"]

log = logging.getLogger(__name__)


async def run_dialogue(
    agent: DialogueAgent,
    intents: Any,
    statuses: Any,
    publish: Callable[[Outgoing], None],
    *,
    period: float = 0.1,
    registry: Any = None,
    invalid: Callable[[], None] | None = None,
) -> None:
    """Serve the dialogue until cancelled.

    Args:
        agent: the dialogue.
        intents: a subscription yielding raw intent payloads (``bytes``) via ``recv_batch``.
        statuses: a subscription yielding decoded ``loci.base_status/1`` dicts, or None.
        publish: publishes an :class:`Outgoing` (validates it).
        period: seconds between :meth:`DialogueAgent.tick` calls.
        registry: the schema registry (default ``agent.bus.schemas.SCHEMAS``).
        invalid: called for each malformed intent (the runtime counts it).
    """
    if registry is None:
        from agent.bus.schemas import SCHEMAS

        registry = SCHEMAS

    ratelog = RateLimitedLog(log)

    def send(out: Iterable[Outgoing]) -> None:
        for o in out:
            try:
                publish(o)
            except Exception as exc:  # a bug: say so, keep serving
                ratelog(
                    f"publish {o.stream}",
                    "could not publish on %s: %s (%.300s)",
                    o.stream,
                    exc,
                    o.message,
                    exc=exc,
                )

    def refuse(payload: bytes, reason: str) -> None:
        if invalid is not None:
            invalid()
        reply = agent.error_for_raw(payload, reason)
        send([reply] if reply is not None else [])

    async def serve_intents() -> None:
        while True:
            for payload in await intents.recv_batch(16):
                try:
                    intent = registry.decode(payload, "loci.intent/1")
                except ProtocolError as exc:
                    ratelog(
                        "invalid intent",
                        "dialogue/intent: dropped an invalid intent: %s",
                        exc,
                        level=logging.WARNING,
                    )
                    refuse(payload, str(exc))
                    continue
                except Exception as exc:  # a decoder bug: the intent is lost, the dialogue is not
                    ratelog("decode intent", "dialogue/intent: decoding an intent failed: %s", exc, exc=exc)
                    refuse(payload, "the intent could not be read")
                    continue
                send(await agent.handle(intent))

    async def serve_statuses() -> None:
        while True:
            for status in await statuses.recv_batch(16):
                send(agent.on_base_status(status))

    async def ticks() -> None:
        while True:
            await asyncio.sleep(period)
            send(await agent.tick())

    tasks = [
        asyncio.create_task(serve_intents(), name="dialogue intents"),
        asyncio.create_task(ticks(), name="dialogue tick"),
    ]
    if statuses is not None:
        tasks.append(asyncio.create_task(serve_statuses(), name="dialogue status"))
    try:
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
        for t in done:
            exc = t.exception()
            if exc is not None and not isinstance(exc, BusClosed):
                raise exc
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await t
