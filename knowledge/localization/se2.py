"""Planar rigid transforms (SE(2)) on arrays of poses.

A pose is ``(x, y, theta)``: metres, metres, radians. Functions take ``(3,)`` or ``(N, 3)``
arrays and broadcast; angles come out wrapped to ``(-π, π]``. ``compose(a, b)`` is ``a ⊕ b``:
``b`` expressed in ``a``'s frame, moved into the frame ``a`` is expressed in.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["between", "compose", "inverse", "transform_points", "wrap"]


def wrap(theta: npt.ArrayLike) -> np.ndarray:
    """Angles wrapped to ``(-π, π]``."""
    t = np.asarray(theta, dtype=np.float64)
    return np.arctan2(np.sin(t), np.cos(t))


def compose(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """``a ⊕ b``: ``(..., 3)``."""
    A = np.asarray(a, dtype=np.float64)
    B = np.asarray(b, dtype=np.float64)
    c, s = np.cos(A[..., 2]), np.sin(A[..., 2])
    return np.stack(
        [
            A[..., 0] + c * B[..., 0] - s * B[..., 1],
            A[..., 1] + s * B[..., 0] + c * B[..., 1],
            wrap(A[..., 2] + B[..., 2]),
        ],
        axis=-1,
    )


def inverse(a: npt.ArrayLike) -> np.ndarray:
    """``⊖a``, so that ``compose(a, inverse(a))`` is the identity: ``(..., 3)``."""
    A = np.asarray(a, dtype=np.float64)
    c, s = np.cos(A[..., 2]), np.sin(A[..., 2])
    return np.stack(
        [-c * A[..., 0] - s * A[..., 1], s * A[..., 0] - c * A[..., 1], wrap(-A[..., 2])], axis=-1
    )


def between(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """``⊖a ⊕ b``: ``b`` seen from ``a`` (the odometry increment from ``a`` to ``b``)."""
    return compose(inverse(a), b)


def transform_points(pose: npt.ArrayLike, points: npt.ArrayLike) -> np.ndarray:
    """``(M, 2)`` points given in ``pose``'s frame, in the frame ``pose`` is expressed in."""
    p = np.asarray(pose, dtype=np.float64)
    q = np.asarray(points, dtype=np.float64)
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.stack([p[0] + c * q[:, 0] - s * q[:, 1], p[1] + s * q[:, 0] + c * q[:, 1]], axis=-1)
