"""MCAP recording and replay of the bus.

``recorder``: :class:`McapSink` (samples → MCAP with Foxglove/JSON schemas) and
:class:`Recorder` (a bus subscriber feeding a sink). ``replay``: reading a recording in
order, also one whose writer crashed, with optional pacing at recorded speed. See
``docs/bus.md``.
"""
