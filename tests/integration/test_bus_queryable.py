"""State queryables: answers from the current state, errors as answers, and a get() that returns."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest

from agent.bus.keys import RobotKeys
from agent.bus.queryable import RequestQueryable, StateCell, StateQueryable, query_state, request
from agent.bus.testing import session_pair, settle
from knowledge.errors import ProtocolError

KEYS = RobotKeys("rosie")


def _graph(n: int) -> dict[str, Any]:
    return {
        "schema": "loci.graph/1",
        "stamp": 10.0 + n,
        "nodes": [{"id": i, "x": float(i), "y": 0.0, "kind": "place", "label": "corridor"} for i in range(n)],
        "edges": [[i, i + 1] for i in range(n - 1)],
    }


def test_a_query_gets_the_current_state_at_once() -> None:
    cell = StateCell("loci.graph/1")
    with session_pair() as (a, b), StateQueryable(a, KEYS.state("graph"), cell) as q:
        settle(b, a)
        (reply,) = query_state(b, KEYS.state("graph"), timeout=5.0)
        assert reply.value is None and reply.error == "no state yet"
        cell.set(_graph(3))
        t0 = time.monotonic()
        (reply,) = query_state(b, KEYS.state("graph"), timeout=5.0)
        elapsed = time.monotonic() - t0
        cell.set(_graph(5))
        (later,) = query_state(b, "loci/rosie/state/**", timeout=5.0)
        assert q.queries == 3
    assert reply.key == "loci/rosie/state/graph" and reply.value == _graph(3)
    assert later.value == _graph(5)
    assert elapsed < 2.5  # finished queries return with their replies, not after the 5 s timeout


def test_a_cell_still_loading_answers_with_its_pending_reason_never_an_empty_state() -> None:
    cell = StateCell("loci.graph/1", pending="starting: the saved map is loading")
    with session_pair() as (a, b), StateQueryable(a, KEYS.state("graph"), cell):
        settle(b, a)
        (reply,) = query_state(b, KEYS.state("graph"), timeout=5.0)
        assert reply.value is None and reply.error == "starting: the saved map is loading"
        cell.set(_graph(4))
        (reply,) = query_state(b, KEYS.state("graph"), timeout=5.0)
    assert reply.error is None and reply.value == _graph(4)


def test_a_failing_source_answers_with_an_error_and_keeps_serving() -> None:
    calls = {"n": 0}

    def flaky() -> dict[str, Any]:
        calls["n"] += 1
        if calls["n"] == 1:
            raise RuntimeError("graph is being rebuilt")
        return {"schema": "loci.place/1", "stamp": 1.0, "label": "room", "probabilities": {"room": 1.0}}

    with session_pair() as (a, b), StateQueryable(a, KEYS.state("place"), flaky, "loci.place/1"):
        settle(b, a)
        t0 = time.monotonic()
        (first,) = query_state(b, KEYS.state("place"), timeout=5.0)
        (second,) = query_state(b, KEYS.state("place"), timeout=5.0)
        elapsed = time.monotonic() - t0
    assert first.value is None and first.error is not None and "graph is being rebuilt" in first.error
    assert second.value is not None and second.value["label"] == "room"
    assert elapsed < 4.0


def test_a_state_that_does_not_validate_is_refused_when_set() -> None:
    cell = StateCell("loci.areas/1")
    with pytest.raises(ProtocolError, match="areas"):
        cell.set({"schema": "loci.areas/1", "stamp": 0.0, "areas": [{"id": 0, "label": "room", "nodes": []}]})
    assert cell() is None
    with pytest.raises(ValueError, match="schema_id"):
        StateQueryable.__init__(object.__new__(StateQueryable), None, "k", lambda: None)  # type: ignore[arg-type]


def test_nobody_answering_returns_empty_after_the_timeout() -> None:
    with session_pair() as (_, b):
        t0 = time.monotonic()
        assert query_state(b, "loci/nobody/state/**", timeout=0.3) == []
        assert time.monotonic() - t0 < 3.0


def test_a_request_is_answered_from_the_loop_and_refusals_say_why() -> None:
    """A request queryable hands each validated request to a coroutine on the event loop
    (Zenoh's thread does not wait for it: two slow requests overlap), sends its reply, and
    answers a refusal (ValueError, OSError, LociError) with its message and any other failure
    with the exception's name."""
    key = KEYS.stream("map/save")

    async def handler(req: dict[str, Any]) -> dict[str, Any]:
        folder = req["dir"]
        if folder == "/refused":
            raise ValueError("no map yet")
        if folder == "/broken":
            raise KeyError("bug")
        await asyncio.sleep(1.0)
        return {
            "schema": "loci.map_saved/1",
            "stamp": 1.0,
            "dir": folder,
            "files": [f"{folder}/map.yaml"],
            "frame_id": "odom",
            "resolution": 0.05,
            "origin": [0.0, 0.0, 0.0],
            "width": 3,
            "height": 2,
            "scans": 7,
        }

    def ask(folder: str) -> Any:
        msg = {"schema": "loci.map_save/1", "dir": folder}
        return request(b, key, msg, "loci.map_save/1", timeout=5.0)

    async def main() -> None:
        with RequestQueryable(
            a, key, handler, "loci.map_save/1", "loci.map_saved/1", asyncio.get_running_loop()
        ) as q:
            await asyncio.to_thread(settle, b, a)
            t0 = time.monotonic()
            first, second = await asyncio.gather(asyncio.to_thread(ask, "/x"), asyncio.to_thread(ask, "/y"))
            assert time.monotonic() - t0 < 1.9  # both handled at once, not one after the other
            assert first[0].value["dir"] == "/x" and second[0].value["dir"] == "/y"
            (refused,) = await asyncio.to_thread(ask, "/refused")
            assert refused.value is None and refused.error == "no map yet"
            (broken,) = await asyncio.to_thread(ask, "/broken")
            assert broken.error == "KeyError: 'bug'"
            (empty,) = await asyncio.to_thread(query_state, b, key, 5.0)  # a query without a request
            assert empty.error is not None and "carries a loci.map_save/1 request" in empty.error
            assert q.queries == 5

    with session_pair() as (a, b):
        asyncio.run(main())
