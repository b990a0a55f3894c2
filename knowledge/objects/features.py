"""SIFT keypoints and descriptors of an image (book Sect. 7.3), as plain arrays.

OpenCV's ``cv2.KeyPoint`` objects are turned into a ``(n, 4)`` float32 array at once, so the
rest of the package (and the database files) deal with numbers only. Pixel coordinates
follow OpenCV's convention: pixel centres at integers, ``x`` to the right, ``y`` down.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float32]
GreyImage = npt.NDArray[np.uint8]

#: Version of the feature extraction; stored with every object's descriptors.
FEATURES_VERSION = 1


@dataclass(frozen=True)
class FeatureParams:
    """How SIFT features are extracted (stored with the descriptors of a database).

    Attributes:
        max_side: images with a longer side are shrunk to it first (pixels); keypoint
            coordinates are given back in the original image's pixels.
        n_features: keep at most this many keypoints, the strongest (0: all).
        contrast_threshold: SIFT's contrast threshold (OpenCV's default 0.04).
    """

    max_side: int = 1024
    n_features: int = 0
    contrast_threshold: float = 0.04

    def __post_init__(self) -> None:
        if self.max_side < 32:
            raise ValueError(f"max_side must be at least 32 pixels, got {self.max_side}")
        if self.n_features < 0:
            raise ValueError(f"n_features must be >= 0 (0: all), got {self.n_features}")
        if not 0 < self.contrast_threshold < 1:
            raise ValueError(f"contrast_threshold must be in (0, 1), got {self.contrast_threshold}")

    def key(self) -> dict[str, float | int]:
        """A plain-JSON description, stored beside the descriptors."""
        return {
            "version": FEATURES_VERSION,
            "max_side": self.max_side,
            "n_features": self.n_features,
            "contrast_threshold": self.contrast_threshold,
        }


@dataclass(frozen=True, eq=False)
class Features:
    """SIFT features of one image.

    Attributes:
        keypoints: ``(n, 4)`` float32: ``x, y`` (pixels), ``size`` (pixels), ``angle`` (degrees).
        descriptors: ``(n, 128)`` float32 (SIFT's values are whole numbers in 0..255).
        image_size: ``(width, height)`` of the image, pixels.
    """

    keypoints: FloatArray
    descriptors: FloatArray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        kp = np.asarray(self.keypoints, dtype=np.float32).reshape(-1, 4)
        d = np.asarray(self.descriptors, dtype=np.float32).reshape(-1, 128)
        if kp.shape[0] != d.shape[0]:
            raise ValueError(f"{kp.shape[0]} keypoints but {d.shape[0]} descriptors")
        w, h = int(self.image_size[0]), int(self.image_size[1])
        if w < 1 or h < 1:
            raise ValueError(f"image_size must be positive (width, height), got {self.image_size}")
        object.__setattr__(self, "keypoints", kp)
        object.__setattr__(self, "descriptors", d)
        object.__setattr__(self, "image_size", (w, h))

    def __len__(self) -> int:
        return int(self.keypoints.shape[0])

    @property
    def points(self) -> FloatArray:
        """``(n, 2)`` keypoint positions, pixels."""
        return self.keypoints[:, :2]


def to_grey(image: npt.ArrayLike) -> GreyImage:
    """A ``(h, w)`` uint8 grey image from a ``(h, w)``, ``(h, w, 3)`` BGR or ``(h, w, 4)`` BGRA uint8 one."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 2:
        return np.ascontiguousarray(img)
    if img.ndim == 3 and img.shape[2] == 1:
        return np.ascontiguousarray(img[:, :, 0])
    if img.ndim == 3 and img.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        return np.asarray(cv2.cvtColor(np.ascontiguousarray(img), code), dtype=np.uint8)
    raise ValueError(f"images must be (h, w), (h, w, 3) or (h, w, 4), got shape {img.shape}")


def _sift(params: FeatureParams) -> cv2.SIFT:
    # cv2.SIFT.create is the typed spelling of cv2.SIFT_create (OpenCV >= 4.4)
    return cv2.SIFT.create(nfeatures=params.n_features, contrastThreshold=params.contrast_threshold)


def extract_features(image: npt.ArrayLike, params: FeatureParams | None = None) -> Features:
    """SIFT keypoints and descriptors of a uint8 image (grey, BGR or BGRA)."""
    p = params or FeatureParams()
    grey = to_grey(image)
    h, w = grey.shape
    if min(h, w) < 16:
        raise ValueError(f"an image of {w} x {h} pixels is too small for SIFT (need at least 16 x 16)")
    scale = min(1.0, p.max_side / max(h, w))
    work: GreyImage = grey
    if scale < 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        work = np.asarray(cv2.resize(grey, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
    kps, desc = _sift(p).detectAndCompute(work, None)
    if desc is None or not kps:
        return Features(np.zeros((0, 4), np.float32), np.zeros((0, 128), np.float32), (w, h))
    kp = np.array([(k.pt[0], k.pt[1], k.size, k.angle) for k in kps], dtype=np.float32)
    if scale < 1.0:
        # pixel centres at integers: x_orig + 0.5 = (x_small + 0.5) / scale
        kp[:, :2] = (kp[:, :2] + 0.5) / scale - 0.5
        kp[:, 2] /= scale
    return Features(kp, np.asarray(desc, dtype=np.float32), (w, h))
