"""Simulated twins of the drivers: virtual LMS, base and camera over a simulated world."""

#: What a ``--world`` may name, for every simulator command (:func:`drivers.sim.world.load_world`).
WORLD_HELP = (
    "gen:SEED (a generated office), tour:SEED (a generated tour office), demo:SEED (the guided "
    "tour's world), a map_server .yaml, or an image with --resolution"
)
