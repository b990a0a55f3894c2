"""The dialogue process (``loci dialogue``): console or recogniser text in, intents out, replies spoken.

``grammar`` turns a tutor's utterance into a ``loci.intent/1``; ``referring`` renders the
robot's answers with referring expressions ("a room", "the living room", "the room with the
television"); ``speech`` speaks through espeak-ng; ``transcript`` logs who said what;
``process`` is the program joining them to the agent over Zenoh. See ``docs/dialogue.md``.
"""
