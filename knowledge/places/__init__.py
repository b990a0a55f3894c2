"""The places layer: scan features (book App. A, B), place models made of the decision lists of
:mod:`knowledge.learning`, the labeling of a whole map, relaxation labeling (Sect. 4.5) and the
regions of a labelled map with their heuristic correction (Sect. 4.7)."""
