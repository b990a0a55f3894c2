"""The topological layer (book Sect. 7.2.3): areas of the navigation graph split at doorways,
their consistency and persistence, the labelled map turned into a topological map document
(:mod:`~knowledge.topology.pipeline`) with pictures, and room-segmentation scores."""
