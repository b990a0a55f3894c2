"""The live view: the agent's layers served to the Foxglove app over its WebSocket protocol.

:mod:`agent.live.config` is ``[foxglove]`` (and ``--foxglove [HOST:]PORT``),
:mod:`agent.live.layers` builds the Foxglove messages (grids, scenes, transforms) from the
pipeline's results without any I/O, :mod:`agent.live.server` runs the ``foxglove-sdk``
server and decides what to send, :mod:`agent.live.layout` writes the layout file of
``deploy/foxglove/``. ``docs/foxglove.md`` describes it for users.
"""
