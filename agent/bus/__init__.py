"""The Zenoh bus: key expressions, sessions, codecs, the thread→asyncio bridge, queryables.

=====================  ===============================================================
module                 what it holds
=====================  ===============================================================
``keys``               ``loci/<robot>/<stream>`` keys, the stream table, delivery policies
``session``            :class:`BusConfig`, opening and closing Zenoh sessions
``bridge``             subscriptions awaited in asyncio, publishers, per-stream counters
``codecs``             our messages ↔ Foxglove protobuf / versioned JSON; MCAP schemas
``schemas``            the JSON message schemas and their validation
``protowire``          the protobuf wire format (decoding Foxglove messages)
``scene``              ``foxglove.SceneUpdate`` pictures of the graph and the areas
``queryable``          state queryables and ``get``
``diagnostics``        the counters as a ``loci.diagnostics/1`` message
=====================  ===============================================================

See ``docs/bus.md``. The modules import Zenoh and the Foxglove SDK; import them where they
are used (the CLI imports them inside its handlers).
"""
