"""The navigation layer (Sect. 7.2.2): the graph of nodes dropped along the robot's path,
doorway detection from laser scans, and the graph's JSON document."""

from knowledge.navigation.doorways import Doorway, DoorwayDetector, DoorwayParams
from knowledge.navigation.graph import GraphParams, GraphUpdate, NavigationGraph, Node

__all__ = [
    "Doorway",
    "DoorwayDetector",
    "DoorwayParams",
    "GraphParams",
    "GraphUpdate",
    "NavigationGraph",
    "Node",
]
