"""The places layer (book Ch. 3 and 4): scan features (App. A, B), the place model, labeling a
map cell by cell, probabilistic relaxation (Sect. 4.5) and the regions with their heuristic
correction (Sect. 4.7). The learners themselves are in :mod:`knowledge.learning`."""
