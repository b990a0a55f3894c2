"""Instance recognition with SIFT (book Sect. 7.3): features, ratio test, RANSAC homography.

The robot recognises *instances*, not categories: every object was shown to it beforehand in
one or more training images (a flat, mostly frontal picture of the object, cropped to it;
see :mod:`knowledge.objects.database`). Recognition in a camera image goes:

1. SIFT keypoints and descriptors of the image (:func:`~knowledge.objects.features.extract_features`).
2. Each image descriptor's ``k`` nearest training descriptors over the whole database
   (one FLANN kd-forest over every training image).
3. Lowe's ratio test, with the competitor chosen so that training images of the same object
   do not compete with each other: a match to training image ``v`` of object ``o`` is kept
   when its distance is below ``ratio`` times the nearer of (a) the nearest descriptor of
   any *other* object and (b) the second-nearest descriptor of image ``v`` itself (a
   repeated pattern in one picture is ambiguous, the same point in two pictures is not).
4. One match per training keypoint (the nearest): a lattice cannot pile up on one point.
5. Per training image with enough matches, a RANSAC homography (``cv2.findHomography``).
6. Plausibility: a finite, orientation-preserving homography; the training image's outline
   projects in front of the camera to a convex quadrilateral of reasonable area with
   bounded foreshortening; the inliers cover a reasonable part of the training image.
   Then at least ``min_inliers`` inliers.
7. Per object, the training image with the best score wins; a frame may show several objects.

The thresholds' defaults come from measurements on rendered scenes (``docs/objects.md``).
Pixel coordinates follow OpenCV's convention (pixel centres at integers, ``u`` to the
right, ``v`` down). Bearings are radians, positive to the *left* of the optical axis
(counter-clockwise seen from above, like a robot's yaw).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
import numpy.typing as npt

from knowledge.objects.database import ObjectDatabase, TrainingView
from knowledge.objects.features import FeatureParams, Features, FloatArray, extract_features

F64Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class RecognitionParams:
    """Thresholds of the recogniser (defaults measured; see ``docs/objects.md``).

    Attributes:
        ratio: Lowe's ratio test threshold.
        k: nearest training descriptors looked at per image descriptor.
        min_matches: tentative matches a training image needs before RANSAC is tried.
        min_inliers: RANSAC inliers a detection needs.
        ransac_reproj: RANSAC reprojection threshold, pixels.
        min_area_px: the projected outline's smallest area, pixels².
        max_area_factor: the projected outline's largest area, in image areas.
        max_side_ratio: the largest ratio between opposite sides of the projected outline
            (foreshortening; 4 allows about 75° of yaw).
        min_inlier_spread: the inliers' convex hull must cover at least this share of the
            training image's area (chance inliers bunch up).
        flann_checks: leaves the FLANN search visits (more: exacter and slower).
    """

    ratio: float = 0.75
    k: int = 6
    min_matches: int = 8
    min_inliers: int = 12
    ransac_reproj: float = 5.0
    min_area_px: float = 300.0
    max_area_factor: float = 4.0
    max_side_ratio: float = 4.0
    min_inlier_spread: float = 0.02
    flann_checks: int = 64

    def __post_init__(self) -> None:
        if not 0 < self.ratio < 1:
            raise ValueError(f"ratio must be in (0, 1), got {self.ratio}")
        if self.k < 2:
            raise ValueError(f"k must be >= 2, got {self.k}")
        if self.min_matches < 4 or self.min_inliers < 4:
            raise ValueError("a homography needs min_matches >= 4 and min_inliers >= 4")
        if self.ransac_reproj <= 0 or self.min_area_px < 0 or self.max_area_factor <= 0:
            raise ValueError("ransac_reproj and max_area_factor must be > 0, min_area_px >= 0")
        if self.max_side_ratio < 1 or not 0 <= self.min_inlier_spread < 1:
            raise ValueError("need max_side_ratio >= 1 and 0 <= min_inlier_spread < 1")
        if self.flann_checks < 1:
            raise ValueError(f"flann_checks must be >= 1, got {self.flann_checks}")


@dataclass(frozen=True, eq=False)
class Detection:
    """One recognised object in one image.

    Attributes:
        name: the object's instance name, from the database.
        kind: its ontology class name ("Television").
        inliers: RANSAC inliers of the homography.
        score: confidence in (0, 1): ``inlier ratio × inliers / (inliers + min_inliers)``,
            so both a clean fit and many inliers count (0.5 at ``min_inliers`` perfect inliers).
        homography: ``(3, 3)`` training image pixels → image pixels.
        corners: ``(4, 2)`` the training image's corners in the image: top-left, top-right,
            bottom-right, bottom-left (pixels; may reach outside the image).
        matches: tentative matches (after the ratio test) with that training image.
        image_index: which of the object's training images matched best.
        centre: ``(u, v)`` the training image's centre in the image, pixels.
        bearing: direction of ``centre`` from the optical axis, radians, positive to the left;
            None when no intrinsics were given.
    """

    name: str
    kind: str
    inliers: int
    score: float
    homography: F64Array = field(repr=False)
    corners: F64Array = field(repr=False)
    matches: int = 0
    image_index: int = 0
    centre: tuple[float, float] = (math.nan, math.nan)
    bearing: float | None = None

    def to_json(self) -> dict[str, object]:
        """Plain JSON (pixels; the bearing in degrees, for people)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "inliers": self.inliers,
            "matches": self.matches,
            "score": round(self.score, 4),
            "image_index": self.image_index,
            "centre": [round(self.centre[0], 2), round(self.centre[1], 2)],
            "corners": [[round(float(x), 2), round(float(y), 2)] for x, y in self.corners],
            "homography": [[float(v) for v in row] for row in self.homography],
            "bearing_deg": None if self.bearing is None else round(math.degrees(self.bearing), 3),
        }


def bearing_of(u: float, intrinsics: npt.ArrayLike) -> float:
    """Direction (radians, positive to the left of the optical axis) of image column ``u``.

    ``intrinsics`` is the ``(3, 3)`` pinhole matrix K (fx, cx in pixels); the camera is
    assumed level (the bearing is the horizontal angle of the ray).
    """
    K = np.asarray(intrinsics, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0:
        raise ValueError(f"intrinsics must be a finite (3, 3) matrix with fx > 0, got {K.tolist()}")
    return math.atan2(float(K[0, 2]) - u, float(K[0, 0]))


class ObjectRecogniser:
    """Recognises the objects of a database (or of a list of training views) in images.

    The constructor loads every training view and indexes its descriptors (a missing or
    damaged object file is the database's :class:`~knowledge.errors.ModelError`);
    :meth:`recognise` returns one :class:`Detection` per recognised object, best score
    first. Not thread-safe (FLANN's matcher is not); use one per thread.
    """

    def __init__(
        self,
        database: ObjectDatabase | Sequence[TrainingView],
        params: RecognitionParams | None = None,
        feature_params: FeatureParams | None = None,
    ) -> None:
        self.params = params or RecognitionParams()
        if isinstance(database, ObjectDatabase):
            views = database.views()
            self.feature_params = feature_params or database.feature_params
        else:
            views = list(database)
            self.feature_params = feature_params or FeatureParams()
        kinds: dict[str, str] = {}
        for v in views:
            if kinds.setdefault(v.name, v.kind) != v.kind:
                raise ValueError(
                    f"object {v.name!r} has training views of two kinds: {kinds[v.name]!r}, {v.kind!r}"
                )
        self.views = tuple(views)
        obj_of_name = {n: i for i, n in enumerate(sorted(kinds))}
        counts = np.array([len(v.features) for v in views], dtype=np.int64)
        self._view_of_desc: IntArray = np.repeat(np.arange(len(views), dtype=np.int64), counts)
        self._obj_of_view: IntArray = np.array([obj_of_name[v.name] for v in views], dtype=np.int64)
        self._n_desc = int(counts.sum())
        self._points: FloatArray = (
            np.concatenate([v.features.points for v in views])
            if self._n_desc
            else np.zeros((0, 2), np.float32)
        )
        self._matcher: cv2.FlannBasedMatcher | None = None
        if self._n_desc >= 2:
            index_params: dict[str, bool | int | float | str] = {
                "algorithm": 1,
                "trees": 4,
            }  # FLANN_INDEX_KDTREE
            self._matcher = cv2.FlannBasedMatcher(index_params, {"checks": self.params.flann_checks})
            self._matcher.add([np.concatenate([v.features.descriptors for v in views])])
            self._matcher.train()

    @property
    def object_names(self) -> list[str]:
        """Names of the objects known (sorted)."""
        return sorted({v.name for v in self.views})

    def recognise(
        self,
        image: npt.ArrayLike | None = None,
        *,
        features: Features | None = None,
        intrinsics: npt.ArrayLike | None = None,
    ) -> list[Detection]:
        """The objects recognised in ``image`` (or in its precomputed ``features``), best score first.

        Args:
            image: uint8 ``(h, w)`` grey or ``(h, w, 3)`` BGR.
            features: the image's features, if already extracted (then ``image`` may be None).
            intrinsics: ``(3, 3)`` K of the camera; when given, detections carry bearings.
        """
        if features is None:
            if image is None:
                raise ValueError("recognise() needs an image or its features")
            features = extract_features(image, self.feature_params)
        K = None if intrinsics is None else np.asarray(intrinsics, dtype=np.float64)
        if K is not None:
            bearing_of(0.0, K)  # validates K
        if self._matcher is None or len(features) < 2:
            return []
        best: dict[str, Detection] = {}
        for view_idx, (q_idx, t_idx) in self._tentative_matches(features.descriptors).items():
            det = self._verify(view_idx, features, q_idx, t_idx, K)
            if det is not None and (det.name not in best or _key(det) < _key(best[det.name])):
                best[det.name] = det
        return sorted(best.values(), key=_key)

    def _tentative_matches(self, desc: FloatArray) -> dict[int, tuple[IntArray, IntArray]]:
        """Ratio-tested matches grouped by training view: (image indices, training indices)."""
        assert self._matcher is not None
        p = self.params
        k = min(p.k, self._n_desc)
        rows = [r for r in self._matcher.knnMatch(desc, k=k) if len(r) == k]
        if not rows:
            return {}
        q = np.array([r[0].queryIdx for r in rows], dtype=np.int64)
        train = np.array([[m.trainIdx for m in r] for r in rows], dtype=np.int64)  # (n, k)
        dist = np.array([[m.distance for m in r] for r in rows], dtype=np.float64)
        view = self._view_of_desc[train]
        obj = self._obj_of_view[view]
        same_obj = obj == obj[:, :1]
        # the nearest descriptor of another object (or the k-th distance, a lower bound of it)
        other = ~same_obj
        first_other = np.argmax(other, axis=1)
        d_other = np.where(other.any(axis=1), dist[np.arange(len(q)), first_other], dist[:, -1])
        # per neighbour: is it the first of its view, and the distance of its view's next one
        same_view = view[:, :, None] == view[:, None, :]  # (n, k, k)
        earlier = np.tril(np.ones((k, k), dtype=bool), -1)  # [j, j'] with j' < j
        first_in_view = ~(same_view & earlier[None]).any(axis=2)
        d_second = np.where(same_view & earlier.T[None], dist[:, None, :], np.inf).min(axis=2)
        keep = same_obj & first_in_view & (dist < p.ratio * np.minimum(d_other[:, None], d_second))
        qi, ji = np.nonzero(keep)
        q_sel, t_sel, d_sel, v_sel = q[qi], train[qi, ji], dist[qi, ji], view[qi, ji]
        # one match per training keypoint: the nearest
        order = np.lexsort((d_sel, t_sel))
        q_sel, t_sel, v_sel = q_sel[order], t_sel[order], v_sel[order]
        first = np.ones(len(t_sel), dtype=bool)
        first[1:] = t_sel[1:] != t_sel[:-1]
        q_sel, t_sel, v_sel = q_sel[first], t_sel[first], v_sel[first]
        out: dict[int, tuple[IntArray, IntArray]] = {}
        for v in np.unique(v_sel):
            m = v_sel == v
            if int(m.sum()) >= p.min_matches:
                out[int(v)] = (q_sel[m], t_sel[m])
        return out

    def _verify(
        self, view_idx: int, features: Features, q_idx: IntArray, t_idx: IntArray, K: F64Array | None
    ) -> Detection | None:
        p = self.params
        view = self.views[view_idx]
        src = np.ascontiguousarray(self._points[t_idx], dtype=np.float32)
        dst = np.ascontiguousarray(features.points[q_idx], dtype=np.float32)
        found, mask = cv2.findHomography(
            src, dst, cv2.RANSAC, p.ransac_reproj, maxIters=2000, confidence=0.995
        )
        if found is None or mask is None:
            return None
        H = np.asarray(found, dtype=np.float64)
        inl = mask.ravel().astype(bool)
        n_in = int(inl.sum())
        if n_in < p.min_inliers:
            return None
        tw, th = view.features.image_size
        outline = np.array([[-0.5, -0.5], [tw - 0.5, -0.5], [tw - 0.5, th - 0.5], [-0.5, th - 0.5]])
        corners = plausible_outline(H, outline, features.image_size, p)
        if corners is None:
            return None
        if cv2.contourArea(cv2.convexHull(src[inl])) < p.min_inlier_spread * tw * th:
            return None
        c = project(H, np.array([[(tw - 1) / 2.0, (th - 1) / 2.0]]))[0]
        ratio = n_in / len(q_idx)
        return Detection(
            name=view.name,
            kind=view.kind,
            inliers=n_in,
            score=ratio * n_in / (n_in + p.min_inliers),
            homography=H,
            corners=corners,
            matches=len(q_idx),
            image_index=view.image_index,
            centre=(float(c[0]), float(c[1])),
            bearing=None if K is None else bearing_of(float(c[0]), K),
        )


def _key(d: Detection) -> tuple[float, int, str]:
    """Sort key: best score first, then more inliers, then by name."""
    return (-d.score, -d.inliers, d.name)


def project(H: F64Array, pts: F64Array) -> F64Array:
    """``(n, 2)`` points mapped by the ``(3, 3)`` homography ``H``."""
    ph = np.hstack([pts, np.ones((len(pts), 1))]) @ H.T
    return np.asarray(ph[:, :2] / ph[:, 2:3], dtype=np.float64)


def plausible_outline(
    H: F64Array, outline: F64Array, image_size: tuple[int, int], p: RecognitionParams
) -> F64Array | None:
    """The ``(4, 2)`` projection of a training image's ``outline`` (its corners, clockwise from
    top-left), or None when ``H`` cannot be a view of a flat picture seen from the front:
    not finite, mirrored, a corner behind the camera, not convex, too small or too large for
    the ``(width, height)`` image, or foreshortened beyond ``p.max_side_ratio``."""
    if not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        return None
    Hn = H / H[2, 2]
    if np.linalg.det(Hn[:2, :2]) <= 0:  # a picture seen from its front keeps its orientation
        return None
    w = np.hstack([outline, np.ones((4, 1))]) @ Hn.T
    if np.any(w[:, 2] <= 1e-9):  # a corner behind the camera: the outline wraps through infinity
        return None
    quad = w[:, :2] / w[:, 2:3]
    q32 = quad.astype(np.float32).reshape(-1, 1, 2)
    if not cv2.isContourConvex(q32):
        return None
    area = abs(float(cv2.contourArea(q32)))
    iw, ih = image_size
    if not p.min_area_px <= area <= p.max_area_factor * iw * ih:
        return None
    sides = np.hypot(*(np.roll(quad, -1, axis=0) - quad).T)  # top, right, bottom, left
    if np.any(sides < 1e-6):
        return None
    for a, b in ((sides[0], sides[2]), (sides[1], sides[3])):
        if max(a, b) / min(a, b) > p.max_side_ratio:
            return None
    return np.asarray(quad, dtype=np.float64)
