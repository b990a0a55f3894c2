"""The camera's twin: a :class:`~drivers.camera.CameraSource` whose frames a renderer draws.

:class:`SimCameraSource` reads frames from anything with ``render(pose) -> image`` (a
:class:`Renderer`: the simulator's :class:`sim.camera_view.VirtualCamera`) at the robot's pose,
at a frame rate, through the same :class:`~drivers.camera.CameraSource` machinery as a real
camera (threads, reconnection, JPEG encoding), so the agent reads it exactly as a real one.
``open_camera("sim://", world=..., pose=...)`` builds one through
:func:`sim.camera_view.camera_source`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from drivers.camera.base import CameraSource
from drivers.messages import Pose2D
from knowledge.errors import DeviceError


class Renderer(Protocol):
    """What the camera twin needs of a world: an image of it seen from the robot's pose."""

    def render(self, robot: Pose2D) -> np.ndarray:
        """``(h, w, 3)`` uint8 BGR."""
        ...


class SimCameraSource(CameraSource):
    """A camera source whose frames ``renderer`` draws at the robot's pose.

    Args:
        renderer: what draws the frames (``renderer.render(pose)``).
        pose: the robot's pose, or a callable returning it (called from the capture thread,
            e.g. ``lambda: base.true_pose``).
        rate_hz: frames per second (default 10).
        **kwargs: the :class:`CameraSource` options.

    ``unplug()`` / ``replug()`` make reads and re-openings fail and succeed again, to exercise
    reconnection as with a real cable.
    """

    def __init__(
        self,
        renderer: Renderer,
        pose: Pose2D | Callable[[], Pose2D],
        *,
        rate_hz: float | None = 10.0,
        **kwargs: Any,
    ) -> None:
        kwargs.setdefault("frame_id", "camera")
        super().__init__("sim", rate_hz=rate_hz, **kwargs)
        self.camera = renderer
        if isinstance(pose, Pose2D):
            fixed = pose
            self._pose: Callable[[], Pose2D] = lambda: fixed
        else:
            self._pose = pose
        self.connected = True

    def unplug(self) -> None:
        """Simulate a pulled cable: reads fail until :meth:`replug`."""
        self.connected = False

    def replug(self) -> None:
        self.connected = True

    def _open(self) -> None:
        if not self.connected:
            raise DeviceError("virtual camera is unplugged")

    def _read(self) -> np.ndarray | None:
        if not self.connected:
            raise DeviceError("virtual camera unplugged")
        return self.camera.render(self._pose())

    def _close(self) -> None:
        pass
