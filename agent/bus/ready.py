"""Processes that say when they are ready, and those that wait for them.

A process of a robot declares the Zenoh liveliness token ``loci/<robot>/ready/<role>``
(:func:`~agent.bus.keys.ready_key`) once it can do its job — the agent when its map and models
are loaded, its kernels compiled and its first scan processed; the simulated robot when its
base runs and its laser streams; the dialogue process when it listens — and the token goes
away with the process (or its session), whatever the way it ends. Anyone can ask which
roles are ready (:func:`ready_roles`) or wait for some (:func:`wait_ready`): the guided-tour
demo starts the tour only when all three are. A liveliness query reaches tokens declared
before it, so nobody has to be listening when a process becomes ready.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Iterable
from typing import Any

import zenoh

from agent.bus.keys import READY_ROLES, ready_key

__all__ = ["declare_ready", "ready_roles", "wait_ready"]


def declare_ready(session: zenoh.Session, robot: str, role: str) -> Any:
    """Declare ``role`` of ``robot`` ready; returns the token (``undeclare()`` it, or close the
    session, when the process stops being ready)."""
    return session.liveliness().declare_token(ready_key(robot, role))


def ready_roles(session: zenoh.Session, robot: str, timeout: float = 1.0) -> set[str]:
    """The roles of ``robot`` whose processes are ready now."""
    out: set[str] = set()
    with contextlib.suppress(zenoh.ZError):
        for reply in session.liveliness().get(ready_key(robot, "*"), timeout=timeout):
            ok = getattr(reply, "ok", None)
            if ok is not None:
                role = str(ok.key_expr).rsplit("/", 1)[-1]
                if role in READY_ROLES:
                    out.add(role)
    return out


async def wait_ready(
    session: zenoh.Session,
    robot: str,
    roles: Iterable[str],
    timeout: float,
    period: float = 0.25,
    *,
    alive: Callable[[], bool] | None = None,
    waiting: Callable[[set[str], float], None] | None = None,
    every: float = 30.0,
) -> set[str]:
    """Wait until every one of ``roles`` is ready, at most ``timeout`` seconds; returns the
    roles that are ready (all of them, unless the time ran out or ``alive()`` said no).

    ``waiting(missing, seconds)`` is called every ``every`` seconds while some are missing (a
    first start on a slow machine compiles its kernels for minutes: say who is still busy).
    """
    want = set(roles)
    t0 = time.monotonic()
    deadline = t0 + timeout
    said = t0
    seen: set[str] = set()
    while True:
        seen = await asyncio.to_thread(ready_roles, session, robot, min(1.0, max(0.1, period * 2)))
        now = time.monotonic()
        if want <= seen or now >= deadline or (alive is not None and not alive()):
            return seen
        if waiting is not None and now - said >= every:
            said = now
            waiting(want - seen, now - t0)
        await asyncio.sleep(period)
