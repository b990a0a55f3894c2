"""Contradicting assertions start a clarification (Sect. 7.2.4.5), with the real conceptual map
(owlready2 + the ontology; contradictions are found from the statements, before reasoning)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
from support.dialogue import Clock, office

from agent.bus.schemas import SCHEMAS
from agent.conceptual_service import ConceptualService
from agent.conversation.agent import DialogueAgent
from knowledge.topology.areas import AreaCreated


def _intent(i: int, kind: str, speaker: str, **args: Any) -> dict[str, Any]:
    msg = {"schema": "loci.intent/1", "id": f"c{i}", "speaker": speaker, "intent": kind, "args": args}
    SCHEMAS.validate(msg)
    return msg


@pytest.mark.slow
def test_a_contradicting_type_is_asked_about_and_the_answer_decides(tmp_path: Path) -> None:
    async def main() -> None:
        world, _, _, room = office()
        world.graph.current = room[1]
        async with ConceptualService(tmp_path / "concepts.sqlite3", debounce=0.05) as concepts:
            agent = DialogueAgent(world, concepts, clock=Clock())
            agent.on_area_events([AreaCreated(a.id, a.label, a.nodes) for a in world.areas.areas.values()])
            await agent.tick()
            area = world.areas.area_of(room[1])
            assert area is not None

            async def ask(msg: dict[str, Any]) -> list[dict[str, Any]]:
                out = await agent.handle(msg)
                for o in out:
                    SCHEMAS.validate(o.message)
                return [o.message for o in out]

            (ok,) = await ask(_intent(1, "assert_type", "anna", type="kitchen"))
            assert ok["status"] == "ok" and "contradictions" not in ok["content"]
            # Bob says it is a corridor: the robot classified a room, and a kitchen is a room;
            # nothing changes, the robot asks
            reply, question = await ask(_intent(2, "assert_type", "bob", type="corridor"))
            layers = {c["layer"] for c in reply["content"]["contradictions"]}
            assert layers == {"acquired", "asserted"}, reply["content"]
            assert question["schema"] == "loci.ask/1" and question["choices"][0] == "corridor"
            assert question["about"]["kind"] == "contradiction" and question["about"]["area"] == area.id
            other = question["choices"][1]
            assert other in question["text"] and "Which is it?" in question["text"]
            # not one of the choices: an error reply, the question stays open
            (bad,) = await ask(_intent(3, "answer", "bob", answer="garage", question=question["id"]))
            assert bad["status"] == "error" and "corridor" in bad["reason"]
            # the old word: nothing changes
            (kept,) = await ask(_intent(4, "answer", "bob", answer=other, question=question["id"]))
            assert kept["status"] == "ok" and kept["content"]["kept"] == other
            await concepts.flush()
            text = str(concepts.snapshot()["areas"][str(area.id)])
            assert "Corridor" not in text and "Kitchen" in text, text
            # asked again and answered "corridor": Anna's kitchen goes, but the robot still sees
            # a room, so it does not call it a corridor either; it says so
            _, question = await ask(_intent(5, "assert_type", "bob", type="corridor"))
            (answer,) = await ask(_intent(6, "answer", "bob", answer="corridor", question=question["id"]))
            assert answer["status"] == "ok" and answer["content"]["kept"] == "room"
            assert "I still see a room here" in answer["text"]
            await concepts.flush()
            text = str(concepts.snapshot()["areas"][str(area.id)])
            assert "Corridor" not in text and "Kitchen" not in text, text

    asyncio.run(main())
