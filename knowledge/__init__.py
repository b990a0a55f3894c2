"""genius-loci's pure core: maps, places, people, navigation, topology, concepts.

Nothing in here waits on sockets, serial lines or the event loop, and nothing opens a
file the caller did not name: every function takes arrays (or paths it was given) and
returns arrays, so the core can be used from a notebook or a test as easily as from the
running agent.
"""
