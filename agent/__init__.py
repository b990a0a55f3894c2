"""genius-loci's runtime: the command line, the asyncio agent, the Zenoh bus and MCAP recording and replay.

``agent`` is the only package that waits on things: it wires the pure core in
``knowledge`` to the devices in ``drivers`` and to the outside world.
"""
