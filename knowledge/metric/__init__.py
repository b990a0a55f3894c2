"""The metric layer: occupancy grids and ray casting."""

from knowledge.metric.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "OccupancyGrid"]
