"""Simulated twins of the devices: they speak the same bytes and APIs as the hardware.

:mod:`drivers.sim.lms` is a SICK LMS 2xx on a pseudo-terminal, :mod:`drivers.sim.base` a
differential-drive base with odometry, :mod:`drivers.sim.camera` a camera source. What they
sense comes from outside, through small protocols (:class:`~drivers.sim.lms.RangeSource`,
:class:`~drivers.sim.base.Terrain`, :class:`~drivers.sim.camera.Renderer`): the simulated
world that implements them is the :mod:`sim` package.
"""
