"""The navigation layer (Sect. 7.2.2): the graph of nodes dropped along the robot's path,
doorway detection from laser scans, and path planning over the graph. (The graph's JSON
document, with the areas, and the consistency checks that need the areas are in
:mod:`knowledge.topology`, the layer above.)"""

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
