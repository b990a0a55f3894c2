"""Two connected Zenoh sessions on loopback, for tests and demos (no router, no scouting).

``with session_pair() as (a, b):`` — ``a`` listens on a free loopback port, ``b`` connects to
it; both are closed when the block ends.

A new subscriber (or queryable) takes a moment to reach the other session, and what is
published before that is lost, although the publisher's ``matching_status`` may already say
True (seen with Zenoh 1.10: a burst right after the declarations vanished about half of the
time). :func:`settle` is a barrier: it returns once every declaration the subscribing
session made so far has reached the publishing session. :func:`wait_until` polls a condition.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import zenoh

from agent.bus.session import BusConfig, close_session, listening_endpoints, open_session


def wait_until(predicate: Callable[[], bool], timeout: float = 5.0, interval: float = 0.005) -> bool:
    """Poll ``predicate`` until it is true (returns True) or ``timeout`` seconds pass (False)."""
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(interval)


def settle(publisher: zenoh.Session, subscriber: zenoh.Session, timeout: float = 5.0) -> None:
    """Return once the declarations ``subscriber`` made so far are known to ``publisher``.

    ``subscriber`` declares a probe subscriber after its others; ``publisher`` puts probes
    until one arrives. Declarations travel in order, so the earlier ones have arrived too.

    Raises:
        TimeoutError: no probe arrived within ``timeout`` seconds (the sessions are not connected).
    """
    key = f"loci-probe/{uuid.uuid4().hex}"
    arrived = threading.Event()
    probe = subscriber.declare_subscriber(key, lambda _: arrived.set())
    try:
        deadline = time.monotonic() + timeout
        while not arrived.wait(0.002):
            if time.monotonic() > deadline:
                raise TimeoutError(f"no probe crossed between the sessions within {timeout} s")
            publisher.put(key, b"")
    finally:
        probe.undeclare()


@contextmanager
def session_pair(timeout: float = 5.0) -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """Two peer sessions connected over ``tcp/127.0.0.1``; raises ``TimeoutError`` if they do not meet."""
    a = open_session(BusConfig())
    b: zenoh.Session | None = None
    try:
        endpoints = listening_endpoints(a)
        if not endpoints:
            raise RuntimeError("the listening session reported no endpoint")
        b = open_session(BusConfig(listen=(), connect=tuple(endpoints)))
        a_zid = str(a.zid())
        if not wait_until(lambda: a_zid in {str(z) for z in b.info.peers_zid()}, timeout):
            raise TimeoutError(f"the second session did not connect to {endpoints} within {timeout} s")
        yield a, b
    finally:
        if b is not None:
            close_session(b)
        close_session(a)
