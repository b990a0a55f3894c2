"""The agent's pure core: synchronous, deterministic, no I/O.

:mod:`~agent.core.pipeline` (the per-scan chain: laser pose, people, local map and rear
beams, place model, doorways, navigation graph, areas), :mod:`~agent.core.odom_sync` (each
scan with the odometry at its stamp, whatever the real timing), :mod:`~agent.core.follow`
(follow-me: a velocity command from a tracked person) and :mod:`~agent.core.mapviz` (the
layered map as one picture). The runtime (:mod:`agent.runtime`) and the replay
(:mod:`agent.recording.offline`) drive them with the same inputs, so a live run and a replay
of its recording build the same map.
"""
