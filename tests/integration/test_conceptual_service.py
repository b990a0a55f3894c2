"""The conceptual service: one owner thread, debounced reasoning, snapshots that never wait."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from agent.conceptual_service import ConceptualService
from knowledge.conceptual import ConceptualMap, JavaNotFound
from knowledge.topology.areas import AreaCreated


@pytest.mark.slow
def test_many_changes_few_reasonings_and_snapshots_do_not_wait(tmp_path: Path) -> None:
    async def main() -> None:
        seen: list[dict[str, Any]] = []
        service = ConceptualService(tmp_path / "c.sqlite3", debounce=0.3, on_reasoned=seen.append)
        await service.start()
        try:
            threads: set[str] = set()

            def note(m: ConceptualMap) -> None:
                threads.add(threading.current_thread().name)

            await service.apply_area_events(
                [AreaCreated(i, "room", frozenset({i})) for i in range(1, 6)],
                {i: "room" for i in range(1, 6)},
            )

            def bucket(i: int) -> Callable[[ConceptualMap], None]:
                return lambda m: m.add_object(f"thing {i}", "bucket", 1 + i % 5, node=i)

            changes = [service.submit(bucket(i)) for i in range(20)]
            changes.append(service.submit(lambda m: m.add_object("couch", "couch", 3, node=3)))
            changes.append(service.submit(note))
            await asyncio.gather(*changes)
            assert threads and all(t.startswith("conceptual") for t in threads)
            # the objects are visible at once; the inference comes with the reasoning
            snap = service.snapshot()
            assert len(snap["objects"]) == 21 and snap["reasoned"] < snap["version"]
            # wait for the debounced reasoning; meanwhile snapshot() answers from the cache
            answered_while_reasoning = 0
            for _ in range(2000):
                if service.reasonings:
                    break
                if service._running is not None:
                    service.snapshot()
                    assert service.resolve("couch").areas == (3,)
                    answered_while_reasoning += 1
                await asyncio.sleep(0.005)
            assert service.reasonings == 1, "22 changes within the debounce → one reasoning"
            assert answered_while_reasoning > 0
            snap = service.snapshot()
            assert snap["areas"]["3"]["types"] == ["LivingRoom", "Room"]
            assert seen and seen[-1]["areas"]["3"]["types"] == ["LivingRoom", "Room"]
            assert service.resolve("living room").areas == (3,)
            # nothing changed: flush does not reason again
            await service.flush()
            assert service.reasonings == 1
            await service.submit(lambda m: m.remove_object("couch"))
            snap = await service.flush()
            assert service.reasonings == 2 and snap["areas"]["3"]["types"] == ["Room"]
        finally:
            await service.close()
        with ConceptualMap(tmp_path / "c.sqlite3") as m:  # saved by the service
            assert m.snapshot()["reasoned"] == m.version and "couch" not in m.snapshot()["objects"]

    asyncio.run(main())


def test_service_errors_surface() -> None:
    async def main() -> None:
        with pytest.raises(JavaNotFound):
            await ConceptualService(java="/nonexistent/java").start()
        async with ConceptualService() as service:
            with pytest.raises(ValueError, match="area class"):
                await service.submit(lambda m: m.set_area(1, "spaceship"))
            assert service.snapshot()["version"] == 0
        with pytest.raises(RuntimeError, match="not started"):
            service.submit(lambda m: None)

    asyncio.run(main())
