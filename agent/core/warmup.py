"""Compile every per-scan kernel before the robot moves.

The chain's kernels are numba functions compiled on their first call (and cached on disk:
later processes load them in milliseconds). A kernel first called while the robot drives
freezes the agent's loop for seconds on a cold cache: in the noisy guided tour the people
masking kernels first ran a metre into "Follow me", the loop stood still 4–6 s, and the
tracked pose never recovered from what the scans read after it (issue 24). So the agent runs
:func:`warm_up` before it opens the laser: a throwaway pipeline with the agent's own
parameters (tracking inline) drives a synthetic scenario that takes every path a real run
takes —

* a front laser (the sparse local map and its rear beams) and a 360° laser;
* a corridor the robot drives along at walking speed, with a side opening (the doorway
  detector's gap) and a person walking ahead of it: the leg detector, leg pairing, the
  tracker's birth and confirmation, the static-cell and seen-through evidence, and —
  once the person has walked farther than ``[people] min_travel`` — the masking kernels
  (``person_beams``, ``fill_masked``, ``unknown_masked``) with a non-empty mask;
* pose tracking from the first scan: the first integration, the incremental field, the
  matcher's local search and, with odometry that jumps once, its fallback search;
* the occupancy map of the run, which the agent integrates every processed scan into
  (:func:`~agent.core.map_files.add_step`; the tracker's own map only with tracking on).

:func:`compiled_kernels` lists the project's compiled numba functions and their signatures;
the tests check that after :func:`warm_up` a real tour compiles nothing more. While the agent
runs, a :class:`CompileWatch` notices a kernel compiled anyway (a path the scenario missed):
it is logged with its name and time and counted in the diagnostics (``extra.compiles``).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from typing import Any

import numpy as np

from agent.core.map_files import add_step
from agent.core.pipeline import TWO_PI, Pipeline, PipelineParams
from drivers.messages import LaserScan, Pose2D
from knowledge.metric.mapping import ScanMapper
from knowledge.people.detector import LegDetector
from knowledge.places.model import PlaceModel

__all__ = ["CompileWatch", "compiled_kernels", "scenario", "warm_up"]

#: The corridor of the scenario: x from, x to, half width (metres), and the side opening's
#: x range on the left wall (a door-wide gap).
CORRIDOR = (-2.0, 18.0, 1.2)
OPENING = (4.0, 4.9)
#: Scans per second of the scenario (an LMS 2xx at 0.5°) and its length in seconds.
RATE = 37.5
SECONDS = 4.0
#: The robot's and the walker's speeds, metres per second; where the walker starts ahead.
ROBOT_SPEED = 0.5
WALKER_SPEED = 1.0
WALKER_AHEAD = 1.0
LEG_RADIUS = 0.06


def _box_ranges(x: float, y: float, angles: np.ndarray, max_range: float) -> np.ndarray:
    """Ranges from ``(x, y)`` along world ``angles`` to the corridor's walls (with its opening)."""
    x0, x1, h = CORRIDOR
    c, s = np.cos(angles), np.sin(angles)
    r = np.full(angles.shape, max_range)
    with np.errstate(divide="ignore", invalid="ignore"):
        for wall_y, opening in ((h, OPENING), (-h, None)):
            t = (wall_y - y) / s
            hx = x + t * c
            ok = (t > 0) & (hx >= x0) & (hx <= x1)
            if opening is not None:
                ok &= ~((hx >= opening[0]) & (hx <= opening[1]))
            r = np.where(ok, np.minimum(r, t), r)
        for wall_x in (x0, x1):
            t = (wall_x - x) / c
            hy = y + t * s
            ok = (t > 0) & (np.abs(hy) <= h)
            r = np.where(ok, np.minimum(r, t), r)
    return r


def _circles(x: float, y: float, angles: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Ranges from ``(x, y)`` along ``angles`` to the nearest of the circles (inf: none)."""
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    dx, dy = centres[None, :, 0] - x, centres[None, :, 1] - y
    along = dx * c + dy * s
    across2 = dx * dx + dy * dy - along * along
    with np.errstate(invalid="ignore"):
        t = along - np.sqrt(radius * radius - across2)
    t = np.where((across2 <= radius * radius) & (t > 0), t, np.inf)
    return np.asarray(t.min(axis=1))


def scenario(full_turn: bool, *, seconds: float = SECONDS) -> list[tuple[LaserScan, Pose2D]]:
    """The synthetic drive (see the module docstring): ``(scan, odometry pose)`` pairs.

    ``full_turn``: a 360° laser (360 beams) instead of a 180° LMS at 0.5° (361 beams). The
    odometry jumps 0.5 m forward once, two thirds of the way (a stalled encoder catching
    up), so that the tracker's fallback search runs too.
    """
    n, fov = (360, TWO_PI) if full_turn else (361, math.pi)
    inc = fov / n if full_turn else fov / (n - 1)
    angle_min = 0.0 if full_turn else -fov / 2
    beams = angle_min + np.arange(n) * inc
    max_range = 30.0
    out: list[tuple[LaserScan, Pose2D]] = []
    steps = int(seconds * RATE)
    for k in range(steps):
        t = k / RATE
        x, y = ROBOT_SPEED * t, 0.1 * math.sin(0.8 * t)
        theta = 0.08 * math.cos(0.8 * t)
        world = theta + beams
        ranges = _box_ranges(x, y, world, max_range)
        wx = WALKER_AHEAD + WALKER_SPEED * t
        swing = 0.15 * math.sin(2 * math.pi * 1.8 * t)
        legs = np.array([[wx + swing, 0.12], [wx - swing, -0.12]])
        ranges = np.minimum(ranges, _circles(x, y, world, legs, LEG_RADIUS))
        odom_x = x + (0.5 if k > 2 * steps // 3 else 0.0)
        stamp = 1000.0 + t
        scan = LaserScan(stamp, k + 1, "laser", angle_min, inc, max_range, ranges.astype(np.float32))
        out.append((scan, Pose2D(odom_x, y, theta, stamp=stamp)))
    return out


def warm_up(
    model: PlaceModel,
    params: PipelineParams | None = None,
    *,
    people_detector: LegDetector | None = None,
) -> float:
    """Run throwaway pipelines on :func:`scenario` (front and 360° lasers) with ``params``
    (tracking inline), so that every kernel of the chain is compiled or loaded from the
    cache; returns the seconds it took."""
    t0 = time.perf_counter()
    prm = replace(params or PipelineParams(), tracking_lag=0)
    for full in (False, True):
        p = Pipeline(model, prm, people_detector=people_detector)
        mapper = ScanMapper()
        try:
            for scan, pose in scenario(full):
                add_step(mapper, p.process(scan, pose))
        finally:
            p.close()
    return time.perf_counter() - t0


def compiled_kernels(
    prefixes: tuple[str, ...] = ("knowledge.", "agent.", "drivers.", "sim."),
) -> dict[str, int]:
    """``{module.function: signatures compiled}`` of every numba function of the project's
    loaded modules (their ``prefixes``)."""
    from numba.core.registry import CPUDispatcher

    out: dict[str, int] = {}
    for name, module in list(sys.modules.items()):
        if module is None or not name.startswith(prefixes):
            continue
        for attr, value in list(vars(module).items()):
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                out[f"{name}.{attr}"] = len(value.signatures)
    return out


class CompileWatch:
    """Numba compilations of the project's functions while armed (a kernel the warm-up did
    not reach, compiled in the middle of the run): their names and seconds, newest last.

    Numba reports each compilation as an event on the thread that compiles; nested ones
    (a kernel calling another) count once, with the outermost's time.
    """

    def __init__(self, prefixes: tuple[str, ...] = ("knowledge.", "agent.", "drivers.", "sim.")) -> None:
        import threading

        from numba.core import event

        self.prefixes = prefixes
        self.compiled: list[tuple[str, float]] = []
        self._local = threading.local()
        self._lock = threading.Lock()
        watch = self

        class _Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                stack = getattr(watch._local, "stack", None)
                if stack is None:
                    stack = watch._local.stack = []
                stack.append(time.perf_counter())

            def on_end(self, ev: Any) -> None:
                stack = getattr(watch._local, "stack", None)
                t0 = stack.pop() if stack else time.perf_counter()
                if stack:  # nested in another compilation: counted with it
                    return
                fn = getattr(ev.data.get("dispatcher"), "py_func", None)
                name = f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', '?')}"
                if name.startswith(watch.prefixes):
                    with watch._lock:
                        watch.compiled.append((name, time.perf_counter() - t0))

        self._listener = _Listener()
        self._event = event
        self.armed = False

    def arm(self) -> CompileWatch:
        """Start listening (call after the warm-up)."""
        if not self.armed:
            self._event.register("numba:compile", self._listener)
            self.armed = True
        return self

    def close(self) -> None:
        if self.armed:
            self._event.unregister("numba:compile", self._listener)
            self.armed = False

    def take(self) -> list[tuple[str, float]]:
        """The compilations since the last call."""
        with self._lock:
            out, self.compiled = self.compiled, []
        return out


def _main(argv: list[str] | None = None) -> int:  # pragma: no cover - `python -m agent.core.warmup`
    """Fill the kernel cache: warm up the bundled model with the agent's default parameters,
    people and tracking on (``make install`` runs this once)."""
    from knowledge.localization.tracking import TrackingParams
    from knowledge.places.model import default_model_path

    model = PlaceModel.load(default_model_path())
    params = PipelineParams(localization=TrackingParams())
    seconds = warm_up(model, params)
    kernels = compiled_kernels()
    print(f"compiled or loaded {sum(kernels.values())} kernel signatures in {seconds:.1f} s")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
