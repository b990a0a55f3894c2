"""The simulator: generated buildings, the world, people and the tutor, the guided tour, routes,
and the simulated robot that puts the device twins of :mod:`drivers.sim` into a world.

Nothing in :mod:`knowledge` or :mod:`drivers` imports this package; the agent's simulator
commands (``loci sim``, ``loci demo``), the evaluations and the tests do.
"""

#: What a ``--world`` may name, for every simulator command (:func:`sim.world.load_world`).
WORLD_HELP = (
    "gen:SEED (a generated office), tour:SEED (a generated tour office), demo:SEED (the guided "
    "tour's world), a map_server .yaml, or an image with --resolution"
)
