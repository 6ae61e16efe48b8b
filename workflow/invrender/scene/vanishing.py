"""The field of view of a room photograph from its vanishing points, when nobody gives it.

PSDR-Room (section 4.1) takes the vertical field of view from PerspectiveFields, a learned model
that cannot be downloaded here. A room is a Manhattan world: its walls, floor, furniture edges and
their textures run along three orthogonal directions, whose images converge on three vanishing
points. Two of them, v1 and v2, in homogeneous image coordinates about the principal point (taken
at the image centre, square pixels), are the images of orthogonal directions (a, b, w f) only for
the focal length f with

    a1 a2 + b1 b2 + w1 w2 f^2 = 0.

Steps: line segments by OpenCV's fast line detector (ximgproc, from opencv-contrib; LSD where it
is absent); vanishing points by RANSAC over pairs of segments, each scored by the length of the
segments that point at it (greedy: a found point's segments are removed, up to ``max_points``);
then of every pair of points that gives a plausible f, the one whose segments are longest in all,
counting a third point that is orthogonal to both. Lines of furniture turned away from the walls
make vanishing points of their own; the orthogonality of the pair and of its third point is what
tells the room's from theirs.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from .images import linear_to_srgb

__all__ = ["VanishingEstimate", "estimate_fov", "detect_segments", "vanishing_points"]

log = logging.getLogger(__name__)

FOV_RANGE_DEG = (20.0, 120.0)  # vertical fields of view taken as plausible


@dataclass
class VanishingEstimate:
    fov_y_deg: float  # vertical field of view
    focal: float  # pixels
    points: np.ndarray  # (K, 3) homogeneous vanishing points (pixel coordinates about the centre)
    weights: np.ndarray  # (K,) summed length of each point's segments, pixels
    pair: tuple[int, int]  # the two points f came from
    segments: int  # segments detected


def detect_segments(image: np.ndarray, min_length: float | None = None) -> np.ndarray:
    """(N, 4) segments x1, y1, x2, y2 (pixels) of a linear RGB or grey image."""
    grey = np.asarray(image, np.float32)
    if grey.ndim == 3:
        grey = grey[..., :3].mean(axis=2) if grey.shape[2] >= 3 else grey[..., 0]
    # Exposure to the 99th percentile and sRGB, as a photograph's 8 bits; a light blur against noise.
    level = float(np.percentile(grey, 99)) or 1.0
    grey8 = np.round(linear_to_srgb(grey / level) * 255).astype(np.uint8)
    grey8 = cv2.GaussianBlur(grey8, (0, 0), 1.0)
    h, w = grey8.shape
    min_length = 0.03 * math.hypot(w, h) if min_length is None else min_length
    if hasattr(cv2, "ximgproc"):
        detector = cv2.ximgproc.createFastLineDetector(length_threshold=int(min_length), do_merge=True)
        lines = detector.detect(grey8)
    else:
        lines = cv2.createLineSegmentDetector().detect(grey8)[0]
    if lines is None:
        return np.zeros((0, 4))
    seg = np.asarray(lines, np.float64).reshape(-1, 4)
    return seg[np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) >= min_length]


def _points_at(seg: np.ndarray, vp: np.ndarray, max_angle_deg: float) -> np.ndarray:
    """Which segments point at the homogeneous point ``vp``: the angle between a segment and the
    line from its midpoint to the point (a direction, for a point at infinity) is small."""
    mid = 0.5 * (seg[:, :2] + seg[:, 2:])
    direction = seg[:, 2:] - seg[:, :2]
    to_vp = vp[:2][None] - mid * vp[2]  # (x - m w): the direction to the point, either sign
    cross = np.abs(direction[:, 0] * to_vp[:, 1] - direction[:, 1] * to_vp[:, 0])
    norm = np.linalg.norm(direction, axis=1) * np.linalg.norm(to_vp, axis=1) + 1e-12
    return cross / norm < math.sin(math.radians(max_angle_deg))


def vanishing_points(
    seg: np.ndarray, max_points: int = 5, iterations: int = 1500, max_angle_deg: float = 1.5, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Greedy RANSAC: up to ``max_points`` homogeneous vanishing points (unit vectors; coordinates
    as the segments'), and the summed length of each one's segments."""
    rng = np.random.default_rng(seed)
    ends1 = np.column_stack([seg[:, :2], np.ones(len(seg))])
    ends2 = np.column_stack([seg[:, 2:], np.ones(len(seg))])
    lines = np.cross(ends1, ends2)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    left = np.ones(len(seg), bool)
    points, weights = [], []
    for _ in range(max_points):
        idx = np.flatnonzero(left)
        if len(idx) < 2:
            break
        p = length[idx] / length[idx].sum()  # long segments are the reliable ones
        i = rng.choice(idx, iterations, p=p)
        j = rng.choice(idx, iterations, p=p)
        cand = np.cross(lines[i], lines[j])[i != j]
        cand = cand[np.linalg.norm(cand, axis=1) > 0]
        cand /= np.linalg.norm(cand, axis=1, keepdims=True)
        best, best_score = None, 0.0
        for vp in cand:
            score = length[idx][_points_at(seg[idx], vp, max_angle_deg)].sum()
            if score > best_score:
                best, best_score = vp, score
        if best is None:
            break
        inliers = left & _points_at(seg, best, max_angle_deg)
        best = _refit(lines[inliers], length[inliers], best)
        inliers = left & _points_at(seg, best, max_angle_deg)
        points.append(best)
        weights.append(length[inliers].sum())
        left &= ~inliers
    return np.array(points).reshape(-1, 3), np.array(weights)


def _refit(lines: np.ndarray, length: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """The point nearest all its lines (least squares, each line normalised and weighted by its
    segment's length): the smallest right singular vector."""
    if len(lines) < 2:
        return fallback
    n = lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(n * np.sqrt(length)[:, None])
    return vt[-1] / np.linalg.norm(vt[-1])


def _focal_squared(v1: np.ndarray, v2: np.ndarray) -> float:
    """f^2 that makes v1 and v2 orthogonal directions (nan when w1 w2 vanishes)."""
    ww = v1[2] * v2[2]
    if abs(ww) < 1e-12:
        return math.nan
    return -(v1[0] * v2[0] + v1[1] * v2[1]) / ww


def _direction(vp: np.ndarray, f: float) -> np.ndarray:
    d = np.array([vp[0], vp[1], vp[2] * f])
    return d / np.linalg.norm(d)


def estimate_fov(image: np.ndarray, max_orthogonality: float = 0.08, seed: int = 0) -> VanishingEstimate | None:
    """The vertical field of view of a photograph (linear RGB, (H, W, 3)) from two orthogonal
    vanishing points, or None when no pair gives a plausible one (then the stage says what to give)."""
    h, w = image.shape[:2]
    seg = detect_segments(image)
    if len(seg) < 4:
        return None
    centred = seg - np.array([w, h, w, h]) / 2  # principal point at the image centre
    scale = max(w, h)
    points, weights = vanishing_points(centred / scale, seed=seed)
    f_lo, f_hi = (h / 2 / math.tan(math.radians(fov) / 2) / scale for fov in FOV_RANGE_DEG[::-1])
    best = None
    for a in range(len(points)):
        for b in range(a + 1, len(points)):
            f2 = _focal_squared(points[a], points[b])
            if not f2 > 0 or not f_lo <= math.sqrt(f2) <= f_hi:
                continue
            f = math.sqrt(f2)
            da, db = _direction(points[a], f), _direction(points[b], f)
            score = weights[a] + weights[b]
            for c in set(range(len(points))) - {a, b}:  # a third room direction confirms the pair
                dc = _direction(points[c], f)
                if abs(dc @ da) < max_orthogonality and abs(dc @ db) < max_orthogonality:
                    score += weights[c]
                    break
            if best is None or score > best[0]:
                best = (score, f, (a, b))
    if best is None:
        return None
    _, f, pair = best
    focal = f * scale
    fov_y = math.degrees(2 * math.atan(h / 2 / focal))
    log.info("field of view from vanishing points: %.1f deg vertical (f = %.1f px, %d segments)", fov_y, focal, len(seg))
    return VanishingEstimate(fov_y, focal, points, weights, pair, len(seg))
