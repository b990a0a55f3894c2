"""Training the bundled place models (``loci places train-default``).

:mod:`agent.training.default_models` makes ``default.npz`` (the agent's model) and
``default_map.npz`` (whole-map labeling) from the labelled IPA maps, generated buildings and
the real labelled Freiburg 079 scans; :mod:`agent.training.labelled_log` feeds that log through
the agent's pipeline as the robot would (its scans for training, its scores for evaluation).
It sits above :mod:`sim` (generated buildings) and :mod:`agent.core` (the pipeline) and below
the commands; docs/places.md, "The bundled models".
"""
