"""The topological layer: regions of one label, the region graph, its heuristic correction
(book Sect. 4.7), the topological map document and pictures, and room-segmentation scores."""
