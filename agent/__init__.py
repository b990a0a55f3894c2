"""genius-loci's runtime: the command line, and (later) the asyncio agent, Zenoh bus and MCAP.

``agent`` is the only package that waits on things: it wires the pure core in
``knowledge`` to the devices in ``drivers`` and to the outside world.
"""
