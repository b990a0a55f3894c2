"""Ready tokens: a process says when it can work, anyone can ask or wait (agent/bus/ready.py)."""

from __future__ import annotations

import asyncio
import time

import pytest

from agent.bus.ready import declare_ready, ready_roles, wait_ready
from agent.bus.testing import session_pair, settle


def test_roles_are_ready_while_their_tokens_live_and_a_late_asker_sees_them() -> None:
    with session_pair() as (a, b):
        settle(b, a)
        assert ready_roles(b, "rosie") == set()
        sim = declare_ready(a, "rosie", "sim")
        agent = declare_ready(a, "rosie", "agent")
        declare_ready(a, "other", "dialogue")  # another robot's: not rosie's
        deadline = time.monotonic() + 5.0
        while ready_roles(b, "rosie") != {"sim", "agent"} and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ready_roles(b, "rosie") == {"sim", "agent"}
        agent.undeclare()
        deadline = time.monotonic() + 5.0
        while ready_roles(b, "rosie") != {"sim"} and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ready_roles(b, "rosie") == {"sim"}

        async def wait() -> tuple[set[str], float]:
            t0 = time.monotonic()
            got = await wait_ready(b, "rosie", ("sim", "dialogue"), timeout=0.6)
            return got, time.monotonic() - t0

        got, waited = asyncio.run(wait())
        assert got == {"sim"} and waited >= 0.5  # the dialogue never came: timed out
        sim.undeclare()
    with pytest.raises(ValueError, match="role"):
        declare_ready(a, "rosie", "base")
