"""The virtual camera: pinhole images of a :class:`~sim.world.SimWorld`.

A 2.5-D renderer. The camera looks horizontally (no pitch or roll) from a mount on the
robot. Walls are the grid's occupied cells extruded to ``wall_height``: one ray per image
column is cast through the grid and the column is shaded by distance (a Wolfenstein-style
ray caster). Floor and ceiling are plain shading by distance. Each object is a flat
vertical picture (:class:`~sim.objects.WorldObject`) whose texture is warped into
place with ``cv2.warpPerspective``; it is drawn only where it is nearer than the wall in
that column (so walls occlude it, even partly), only from its front side, clipped at the
near plane, and nearer objects are drawn over farther ones. Optional blur and noise.

Not modelled: lens distortion, lighting and shadows on objects, pitch/roll, furniture as
3-D bodies (only as pictures), objects occluding walls' shading in the depth sense beyond
the painter's order, motion blur, exposure.

:class:`SimCameraSource` plugs the renderer into :class:`~drivers.camera.CameraSource`, so
the agent reads the virtual camera exactly as a real one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from drivers.messages import Pose2D
from drivers.sim.camera import SimCameraSource
from sim.objects import WorldObject, object_texture
from sim.world import SimWorld

#: Objects nearer than this (metres, along the optical axis) are clipped.
NEAR_PLANE = 0.1
#: How many samples across an object's width estimate its visible fraction.
_VIS_SAMPLES = 64


@dataclass(frozen=True)
class CameraMount:
    """Where the camera sits on the robot.

    Attributes:
        x, y: offset from the robot's origin, metres, in the robot frame (x forward, y left).
        z: height of the optical centre above the floor, metres.
        yaw: direction of the optical axis relative to the robot's heading, radians.
    """

    x: float = 0.0
    y: float = 0.0
    z: float = 1.0
    yaw: float = 0.0


@dataclass(frozen=True)
class ObjectView:
    """Ground truth for one object drawn in a rendering.

    Attributes:
        name, kind: the object's.
        centre: ``(u, v)`` pixel coordinates of the picture's centre (OpenCV's convention:
            pixel centres at integers; may lie outside the image when the object is only
            partly in view).
        bbox: ``(x0, y0, x1, y1)`` pixel box of what was drawn (inclusive-exclusive).
        depth: distance of the picture's centre along the optical axis, metres.
        visible_fraction: share of the picture's width that is in view and not occluded.
    """

    name: str
    kind: str
    centre: tuple[float, float]
    bbox: tuple[int, int, int, int]
    depth: float
    visible_fraction: float


@dataclass(frozen=True, eq=False)
class Rendering:
    """One rendered view: the ``(h, w, 3)`` uint8 BGR image, the world yaw of the optical
    axis (radians), and the objects drawn (farthest first)."""

    image: np.ndarray
    yaw: float
    objects: tuple[ObjectView, ...]


class VirtualCamera:
    """Renders a :class:`SimWorld` for a robot pose.

    Args:
        world: the walls and objects.
        width, height: image size in pixels.
        hfov_deg: horizontal field of view, degrees (square pixels; the vertical one follows).
        mount: the camera's place on the robot.
        wall_height: metres (walls above the camera show up as ceiling beyond).
        max_range: walls farther than this (metres) are not drawn.
        noise_sigma: standard deviation of added Gaussian pixel noise (grey levels).
        blur_sigma: Gaussian blur, pixels (0: none).
        seed: seeds the noise.
    """

    def __init__(
        self,
        world: SimWorld,
        *,
        width: int = 640,
        height: int = 480,
        hfov_deg: float = 60.0,
        mount: CameraMount | None = None,
        wall_height: float = 2.5,
        max_range: float = 15.0,
        noise_sigma: float = 0.0,
        blur_sigma: float = 0.0,
        seed: int = 0,
        wall_colour: tuple[int, int, int] = (200, 205, 210),
        floor_colour: tuple[int, int, int] = (95, 120, 150),
        ceiling_colour: tuple[int, int, int] = (235, 235, 235),
    ) -> None:
        if width < 8 or height < 8:
            raise ValueError(f"image size must be at least 8 x 8 pixels, got {width} x {height}")
        if not 1.0 <= hfov_deg <= 170.0:
            raise ValueError(f"hfov_deg must be between 1 and 170 degrees, got {hfov_deg}")
        if noise_sigma < 0 or blur_sigma < 0:
            raise ValueError("noise_sigma and blur_sigma must be >= 0")
        self.world = world
        self.width, self.height = int(width), int(height)
        self.hfov_deg = float(hfov_deg)
        self.mount = mount or CameraMount()
        if not 0 < self.mount.z < wall_height:
            raise ValueError(
                f"the camera height {self.mount.z} m must be between 0 and wall_height {wall_height} m"
            )
        self.wall_height = wall_height
        self.max_range = max_range
        self.noise_sigma = noise_sigma
        self.blur_sigma = blur_sigma
        self._rng = np.random.default_rng(seed)
        self.fx = (self.width / 2.0) / math.tan(math.radians(self.hfov_deg) / 2.0)
        self.fy = self.fx
        # OpenCV's pixel convention: pixel (i, j) is centred on the integer coordinates (i, j)
        self.cx, self.cy = (self.width - 1) / 2.0, (self.height - 1) / 2.0
        self._wall = np.array(wall_colour, float)
        self._background = self._floor_and_ceiling(
            np.array(floor_colour, float), np.array(ceiling_colour, float)
        )
        # tan of each column's ray angle to the optical axis (positive: to the right)
        self._col_t = (np.arange(self.width) - self.cx) / self.fx

    @property
    def intrinsics(self) -> np.ndarray:
        """``(3, 3)`` intrinsic matrix K (pixels; principal point at the image centre)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def camera_pose(self, robot: Pose2D) -> tuple[float, float, float]:
        """World ``(x, y, yaw)`` of the camera for a robot pose."""
        c, s = math.cos(robot.theta), math.sin(robot.theta)
        m = self.mount
        return (robot.x + c * m.x - s * m.y, robot.y + s * m.x + c * m.y, robot.theta + m.yaw)

    # ------------------------------------------------------------------ rendering
    def render(self, robot: Pose2D) -> np.ndarray:
        """The ``(height, width, 3)`` uint8 BGR image seen from ``robot``'s pose."""
        return self.render_full(robot).image

    def panorama(self, robot: Pose2D, n: int = 8) -> list[Rendering]:
        """``n`` views turning counter-clockwise by 360°/n from the robot's heading ("look around")."""
        if n < 1:
            raise ValueError(f"a panorama needs n >= 1 views, got {n}")
        return [
            self.render_full(Pose2D(robot.x, robot.y, robot.theta + 2 * math.pi * k / n, robot.stamp))
            for k in range(n)
        ]

    def render_full(self, robot: Pose2D) -> Rendering:
        """The image and the ground truth of which objects it shows where."""
        x, y, yaw = self.camera_pose(robot)
        t = self._col_t
        rho, side = self.world.raycast_faces(x, y, yaw - np.arctan(t), self.max_range)
        z_wall = rho / np.sqrt(1.0 + t * t)  # depth along the optical axis: no fish-eye
        img = self._draw_walls(z_wall, side)
        fwd = np.array([math.cos(yaw), math.sin(yaw)])
        lft = np.array([-math.sin(yaw), math.cos(yaw)])
        cam = np.array([x, y])
        drawn = []
        for obj in self.world.objects:
            placed = self._place(obj, cam, fwd, lft, z_wall)
            if placed is not None:
                drawn.append(placed)
        drawn.sort(key=lambda p: -p[1].depth)
        for obj, view, quad, s_range, col_ok in drawn:
            self._draw_object(img, obj, quad, s_range, col_ok, view.bbox)
        if self.blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.blur_sigma)
        if self.noise_sigma > 0:
            noisy = img.astype(np.float32) + self._rng.normal(0.0, self.noise_sigma, img.shape).astype(
                np.float32
            )
            img = np.clip(noisy, 0, 255).astype(np.uint8)
        return Rendering(img, yaw, tuple(view for _, view, *_ in drawn))

    def _floor_and_ceiling(self, floor: np.ndarray, ceiling: np.ndarray) -> np.ndarray:
        v = np.arange(self.height) - self.cy
        with np.errstate(divide="ignore"):
            z_floor = np.where(v > 0, self.fy * self.mount.z / np.maximum(v, 1e-9), np.inf)
            z_ceil = np.where(
                v < 0, self.fy * (self.wall_height - self.mount.z) / np.maximum(-v, 1e-9), np.inf
            )
        col = np.where(
            (v > 0)[:, None],
            floor[None, :] * _shade(z_floor)[:, None],
            ceiling[None, :] * _shade(z_ceil)[:, None],
        )
        return np.broadcast_to(col[:, None, :], (self.height, self.width, 3)).astype(np.uint8)

    def _draw_walls(self, z_wall: np.ndarray, side: np.ndarray) -> np.ndarray:
        img = self._background.copy()
        finite = np.isfinite(z_wall)
        z = np.where(finite, z_wall, 1.0)
        v_top = self.cy + self.fy * (self.mount.z - self.wall_height) / z
        v_bot = self.cy + self.fy * self.mount.z / z
        rows = np.arange(self.height)[:, None]
        mask = finite[None, :] & (rows >= v_top[None, :]) & (rows < v_bot[None, :])
        # faces along the map's y axis a little darker, so corners show
        light = _shade(z) * np.where(side, 0.82, 1.0)
        colour = (self._wall[None, :] * light[:, None]).astype(np.uint8)  # (w, 3)
        img[mask] = np.broadcast_to(colour[None, :, :], img.shape)[mask]
        return img

    def _place(
        self, obj: WorldObject, cam: np.ndarray, fwd: np.ndarray, lft: np.ndarray, z_wall: np.ndarray
    ) -> tuple[WorldObject, ObjectView, np.ndarray, tuple[float, float], np.ndarray] | None:
        """Project an object; None when it is not in view. Returns the object, its ground truth,
        the ``(4, 2)`` pixel quad of the drawn part, the drawn span of its width as fractions
        ``(s0, s1)`` and a per-column bool mask of columns where it is not occluded."""
        centre = np.array([obj.x, obj.y])
        if float(np.dot(cam - centre, obj.normal)) <= 0.0:  # seen from behind or edge-on
            return None
        left_end = centre - obj.right * (obj.width_m / 2.0)
        # depth (along the optical axis) and lateral offset (to the right) of the two ends
        rel0, rel1 = left_end - cam, left_end + obj.right * obj.width_m - cam
        z0, z1 = float(rel0 @ fwd), float(rel1 @ fwd)
        if max(z0, z1) <= NEAR_PLANE:
            return None
        s0, s1 = 0.0, 1.0
        if z0 < NEAR_PLANE:
            s0 = (NEAR_PLANE - z0) / (z1 - z0)
        elif z1 < NEAR_PLANE:
            s1 = (NEAR_PLANE - z0) / (z1 - z0)

        def project(s: np.ndarray, z_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            p = left_end[None, :] + s[:, None] * obj.right[None, :] * obj.width_m - cam[None, :]
            depth = p @ fwd
            u = self.cx + self.fx * (-(p @ lft)) / depth
            v = self.cy + self.fy * (self.mount.z - z_world) / depth
            return u, v, depth

        ztop, zbot = obj.elevation_m + obj.height_m, obj.elevation_m
        ss = np.array([s0, s1, s1, s0])
        u, v, _ = project(ss, np.array([ztop, ztop, zbot, zbot]))
        quad = np.stack([u, v], axis=1)
        # visibility per sample across the width: in front, inside the image, not behind a wall
        s_samp = np.linspace(0.0, 1.0, _VIS_SAMPLES)
        us, _, ds = project(s_samp, np.full(_VIS_SAMPLES, (ztop + zbot) / 2))
        eps = 0.75 * self.world.grid.resolution
        cols = np.round(us).astype(np.int64)
        in_img = (ds > NEAR_PLANE) & (cols >= 0) & (cols < self.width)
        wall_at = z_wall[np.clip(cols, 0, self.width - 1)]
        vis = in_img & (ds <= wall_at + eps)
        # per-column occlusion over the quad's horizontal extent
        u_lo = max(0, math.floor(quad[:, 0].min()))
        u_hi = min(self.width, math.ceil(quad[:, 0].max()) + 1)
        if u_hi <= u_lo:
            return None
        col_ok = np.zeros(self.width, dtype=bool)
        t = self._col_t[u_lo:u_hi]
        ray = fwd[None, :] - t[:, None] * lft[None, :]  # unnormalised; depth along fwd = parameter
        d = centre - cam
        denom = ray[:, 0] * obj.right[1] - ray[:, 1] * obj.right[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (d[0] * obj.right[1] - d[1] * obj.right[0]) / denom
        col_ok[u_lo:u_hi] = np.isfinite(lam) & (lam > NEAR_PLANE) & (lam <= z_wall[u_lo:u_hi] + eps)
        if not col_ok.any() or not vis.any():
            return None
        v_lo = max(0, math.floor(quad[:, 1].min()))
        v_hi = min(self.height, math.ceil(quad[:, 1].max()) + 1)
        if v_hi <= v_lo:
            return None
        ok_cols = np.flatnonzero(col_ok)
        bbox = (int(ok_cols[0]), v_lo, int(ok_cols[-1]) + 1, v_hi)
        cz = obj.elevation_m + obj.height_m / 2.0
        uc, vc, dc = project(np.array([0.5]), np.array([cz]))
        view = ObjectView(
            obj.name, obj.kind, (float(uc[0]), float(vc[0])), bbox, float(dc[0]), float(vis.mean())
        )
        return obj, view, quad, (s0, s1), col_ok

    def _draw_object(
        self,
        img: np.ndarray,
        obj: WorldObject,
        quad: np.ndarray,
        s_range: tuple[float, float],
        col_ok: np.ndarray,
        bbox: tuple[int, int, int, int],
    ) -> None:
        tex = object_texture(obj)
        th, tw = tex.shape[:2]
        x0, y0, x1, y1 = bbox
        # shrink big textures first: warpPerspective has no area averaging and would alias
        proj_w = max(float(np.hypot(*(quad[1] - quad[0]))), float(np.hypot(*(quad[2] - quad[3]))))
        proj_h = max(float(np.hypot(*(quad[3] - quad[0]))), float(np.hypot(*(quad[2] - quad[1]))))
        span = max(s_range[1] - s_range[0], 1e-6)
        scale = min(1.0, 2.0 * max(proj_w / (tw * span), proj_h / th))
        if scale < 0.5:
            tex = cv2.resize(
                tex, (max(2, round(tw * scale)), max(2, round(th * scale))), interpolation=cv2.INTER_AREA
            )
            th, tw = tex.shape[:2]
        # the texture covers its pixels' areas: from -0.5 to size - 0.5 in pixel-centre coordinates
        a, b = s_range[0] * tw - 0.5, s_range[1] * tw - 0.5
        src = np.array([[a, -0.5], [b, -0.5], [b, th - 0.5], [a, th - 0.5]], dtype=np.float32)
        dst = (quad - np.array([x0, y0])).astype(np.float32)
        H = cv2.getPerspectiveTransform(src, dst)
        size = (x1 - x0, y1 - y0)
        warped = cv2.warpPerspective(tex, H, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        alpha = cv2.warpPerspective(
            np.full((th, tw), 255, np.uint8), H, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
        )
        a_f = (alpha.astype(np.float32) / 255.0) * col_ok[x0:x1][None, :].astype(np.float32)
        roi = img[y0:y1, x0:x1].astype(np.float32)
        blended = roi * (1.0 - a_f[..., None]) + warped.astype(np.float32) * a_f[..., None]
        img[y0:y1, x0:x1] = np.clip(blended + 0.5, 0, 255).astype(np.uint8)


def _shade(z: np.ndarray) -> np.ndarray:
    """Brightness factor by distance (metres): 1 up close, fading towards 0.35 far away."""
    return 0.35 + 0.65 / (1.0 + 0.12 * np.asarray(z))


# --------------------------------------------------------------------------- as a camera source
def camera_source(
    world: SimWorld | None = None,
    pose: Pose2D | Callable[[], Pose2D] | None = None,
    *,
    camera: VirtualCamera | None = None,
    width: int = 640,
    height: int = 480,
    hfov_deg: float = 60.0,
    noise_sigma: float = 0.0,
    blur_sigma: float = 0.0,
    seed: int = 0,
    mount: CameraMount | None = None,
    rate_hz: float | None = 10.0,
    **kwargs: Any,
) -> SimCameraSource:
    """The virtual camera as a :class:`~drivers.camera.CameraSource` (what
    ``open_camera("sim://", world=..., pose=...)`` gives): a :class:`VirtualCamera` of
    ``world`` (or a ready ``camera``) rendering from ``pose`` (a :class:`Pose2D`, or a callable
    returning the robot's pose, called from the capture thread, e.g. ``lambda: base.true_pose``).

    Args:
        width, height, hfov_deg, noise_sigma, blur_sigma, seed, mount: :class:`VirtualCamera`
            options (unused with ``camera``).
        rate_hz: frames per second.
        **kwargs: the :class:`~drivers.camera.CameraSource` options.
    """
    if camera is None:
        if world is None:
            raise ValueError("the virtual camera needs world= (a SimWorld) or camera= (a VirtualCamera)")
        camera = VirtualCamera(
            world,
            width=width,
            height=height,
            hfov_deg=hfov_deg,
            noise_sigma=noise_sigma,
            blur_sigma=blur_sigma,
            seed=seed,
            mount=mount,
        )
    if pose is None:
        raise ValueError("the virtual camera needs pose= (a Pose2D or a callable returning the robot's pose)")
    return SimCameraSource(camera, pose, rate_hz=rate_hz, **kwargs)
