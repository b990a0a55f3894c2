"""Localization: where the robot is, from odometry, laser scans and place labels.

* :mod:`~knowledge.localization.se2` — planar poses: compose, invert, relate (arrays).
* :mod:`~knowledge.localization.trajectory` — absolute and relative trajectory errors
  (ATE, RPE) against reference poses.
* :mod:`~knowledge.localization.reference` — matching a log's scans to the scans of its
  SLAM-corrected copy (the reference poses of a raw log).
* :mod:`~knowledge.localization.likelihood` — likelihood fields of occupancy grids.
* :mod:`~knowledge.localization.scan_matching` — correlative search and Gauss–Newton
  refinement of one scan against a likelihood field.
* :mod:`~knowledge.localization.tracking` — pose tracking: odometry corrected by matching
  each scan against the map built so far (or a known map); the ``map → odom`` correction.
* :mod:`~knowledge.localization.tracking_field` — the likelihood field of the map the
  tracker builds as it goes, kept up to date tile by tile where the scans changed it.
* :mod:`~knowledge.localization.motion`, :mod:`~knowledge.localization.mcl`,
  :mod:`~knowledge.localization.semantic` — Monte Carlo localization with the place
  classifier as an extra observation (book Sect. 6.3, eq. 6.3).
"""
