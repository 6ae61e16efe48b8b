"""The field of view of a room photograph from its vanishing points, when nobody gives it.

PSDR-Room (section 4.1) takes the vertical field of view from PerspectiveFields, a learned model
that cannot be downloaded here. A room is a Manhattan world: its walls, floor, furniture edges and
their textures run along three orthogonal directions, whose images converge on three vanishing
points. Two of them, v1 and v2, in homogeneous image coordinates about the principal point (taken
at the image centre, square pixels), are the images of orthogonal directions (a, b, w f) only for
the focal length f with

    a1 a2 + b1 b2 + w1 w2 f^2 = 0.

Steps: line segments by OpenCV's fast line detector (ximgproc, from opencv-contrib; LSD where it
is absent) on the photograph in sRGB, lightly blurred against render noise and contrast-equalised
(CLAHE) so that lines in shadow count; vanishing points by
RANSAC over pairs of segments, each scored by the length of the segments that point at it (greedy:
a found point's segments are removed). Then a search over Manhattan frames rather than a solve from
one pair: one direction is a found vanishing point (each of the three strongest is tried), the
other two turn about it by theta; for each focal length and theta the three vanishing points are
projected and each direction's segment support summed as sqrt(support) (a frame must see all three
directions: the anchor alone explains most segments whatever f is). Lines of furniture turned away
from the walls make vanishing points of their own; they support no orthogonal frame. The focal
length of the best frame gives the field of view; the a1 a2 + b1 b2 + w1 w2 f^2 = 0 relation
above is what ties the frame's points to f.
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
    anchor: int  # the vanishing point the frame was searched about
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
    # Local contrast: a room's lines in shadow (a wainscot, a wall corner) are as telling as those
    # in the light; measured on the synthetic rooms, it halves the worst error.
    grey8 = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(grey8)
    h, w = grey8.shape
    min_length = 0.02 * math.hypot(w, h) if min_length is None else min_length
    if hasattr(cv2, "ximgproc"):
        detector = cv2.ximgproc.createFastLineDetector(length_threshold=int(min_length), do_merge=True)
        lines = detector.detect(grey8)
    else:
        lines = cv2.createLineSegmentDetector().detect(grey8)[0]
    if lines is None:
        return np.zeros((0, 4))
    seg = np.asarray(lines, np.float64).reshape(-1, 4)
    return seg[np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) >= min_length]


def _points_at(seg: np.ndarray, vps: np.ndarray, max_angle_deg: float) -> np.ndarray:
    """(K, N): which segments point at each homogeneous point of ``vps`` (K, 3): the angle between a
    segment and the line from its midpoint to the point (a direction, for a point at infinity) is
    below ``max_angle_deg``."""
    mid = 0.5 * (seg[:, :2] + seg[:, 2:])
    direction = seg[:, 2:] - seg[:, :2]
    to_vp = vps[:, None, :2] - mid[None] * vps[:, None, 2:3]
    cross = np.abs(direction[:, 0] * to_vp[..., 1] - direction[:, 1] * to_vp[..., 0])
    norm = np.linalg.norm(direction, axis=1) * np.linalg.norm(to_vp, axis=-1) + 1e-12
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
        if not len(cand):
            break
        scores = _points_at(seg[idx], cand, max_angle_deg) @ length[idx]
        best = cand[np.argmax(scores)]
        inliers = left & _points_at(seg, best[None], max_angle_deg)[0]
        best = _refit(lines[inliers], length[inliers], best)
        inliers = left & _points_at(seg, best[None], max_angle_deg)[0]
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


def _closeness(mid: np.ndarray, unit: np.ndarray, vps: np.ndarray, max_angle_deg: float) -> np.ndarray:
    """How well each segment (midpoint, unit direction) points at each homogeneous point ``vps``
    (..., 3): 1 - (sin angle / sin max)^2, clipped at 0. Shape (..., N)."""
    v = vps[..., None, :]
    tx = v[..., 0] - mid[:, 0] * v[..., 2]
    ty = v[..., 1] - mid[:, 1] * v[..., 2]
    sin = np.abs(unit[:, 0] * ty - unit[:, 1] * tx) / (np.sqrt(tx * tx + ty * ty) + 1e-12)
    return np.clip(1 - (sin / math.sin(math.radians(max_angle_deg))) ** 2, 0, None)


def _frame_scores(seg, length, anchor, focals, thetas, max_angle_deg):
    """Support of the Manhattan frames (focal f, turn theta about the anchor's direction), (F, T)."""
    mid = 0.5 * (seg[:, :2] + seg[:, 2:])
    unit = (seg[:, 2:] - seg[:, :2]) / length[:, None]
    scores = np.empty((len(focals), len(thetas)))
    for i, f in enumerate(focals):
        d0 = np.array([anchor[0], anchor[1], anchor[2] * f])
        d0 /= np.linalg.norm(d0)
        u = np.cross(d0, [0.0, 0.0, 1.0] if abs(d0[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(d0, u)
        d1 = np.cos(thetas)[:, None] * u + np.sin(thetas)[:, None] * w  # (T, 3)
        d2 = np.cross(d0, d1)
        dirs = np.stack([np.broadcast_to(d0, d1.shape), d1, d2], axis=1)  # (T, 3, 3)
        vps = np.concatenate([dirs[..., :2], dirs[..., 2:] / f], axis=-1)  # homogeneous image points
        closeness = _closeness(mid, unit, vps, max_angle_deg)  # (T, 3, N)
        nearest = closeness == closeness.max(axis=1, keepdims=True)  # each segment counts once
        per_direction = (closeness * nearest * length).sum(axis=2)  # (T, 3)
        # sqrt: a frame is good when all three directions are seen, not when one is seen well
        # (the anchor alone explains most segments whatever the focal length).
        scores[i] = np.sqrt(per_direction).sum(axis=1)
    return scores


def _focal_of_fov(fov_y_deg, h: float, scale: float):
    return h / 2 / np.tan(np.radians(fov_y_deg) / 2) / scale


def estimate_fov(
    image: np.ndarray, max_angle_deg: float = 1.5, anchors: int = 3, seed: int = 0
) -> VanishingEstimate | None:
    """The vertical field of view of a photograph (linear RGB, (H, W, 3)): the focal length of the
    Manhattan frame that the most segment length points into.

    The frame is searched, not solved from a pair of points: one of its directions is a vanishing
    point that RANSAC found (each of the ``anchors`` strongest is tried), the others turn about it
    by theta; for each focal length and theta the three vanishing points are projected and the
    segments that point at them summed. Coarse grid (2 degrees of field of view, 2 of theta),
    then a fine one around the best. None when fewer than 4 segments are found."""
    h, w = image.shape[:2]
    seg = detect_segments(image)
    if len(seg) < 4:
        return None
    scale = max(w, h)
    centred = (seg - np.array([w, h, w, h]) / 2) / scale  # principal point at the image centre
    length = np.hypot(centred[:, 2] - centred[:, 0], centred[:, 3] - centred[:, 1])
    points, weights = vanishing_points(centred, seed=seed, max_angle_deg=max_angle_deg)
    best = None
    coarse_fov = np.arange(FOV_RANGE_DEG[0], FOV_RANGE_DEG[1] + 0.5, 2.0)
    coarse_theta = np.radians(np.arange(0.0, 90.0, 2.0))
    for k in range(min(anchors, len(points))):
        scores = _frame_scores(
            centred, length, points[k], _focal_of_fov(coarse_fov, h, scale), coarse_theta, max_angle_deg
        )
        i, j = np.unravel_index(np.argmax(scores), scores.shape)
        fine_fov = coarse_fov[i] + np.arange(-2.0, 2.01, 0.1)
        fine_theta = coarse_theta[j] + np.radians(np.arange(-2.0, 2.01, 0.2))
        scores = _frame_scores(centred, length, points[k], _focal_of_fov(fine_fov, h, scale), fine_theta, max_angle_deg)
        i, j = np.unravel_index(np.argmax(scores), scores.shape)
        if best is None or scores[i, j] > best[0]:
            best = (scores[i, j], fine_fov[i], k)
    _, fov_y, anchor = best
    focal = float(h / 2 / math.tan(math.radians(fov_y) / 2))
    log.info(
        "field of view from vanishing points: %.1f deg vertical (f = %.1f px, %d segments)", fov_y, focal, len(seg)
    )
    return VanishingEstimate(float(fov_y), focal, points, weights, anchor, len(seg))
