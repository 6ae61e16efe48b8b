"""How well a room box explains the photo, and how far it is from the truth.

- ``mask_iou``: per class, the IoU of the box's exact face labels (``cast_box`` at pixel
  centres) with the photo's wall/floor/ceiling labels, over the pixels that show the room;
- ``depth_error``: the mean absolute difference of the box's depth and the photo's over those
  pixels, in the depth's units and relative to its median;
- ``corner_error``: the mean distance of the box's 8 corners to the truth box's, both in the
  photo's camera frame (so the two worlds need not agree), matched one to one; and the same over
  the truth corners the photo shows (a corner behind the camera or outside the frame, such as
  those of the wall behind it, is not observed, so no method can place it). A depth of unknown
  scale is first aligned to the truth (``truth_scale``: the median ratio over the room's pixels).
"""

from __future__ import annotations

import numpy as np

from ..scene.cameras import project_points
from ..scene.types import Camera
from .box import BOX_CLASSES, RoomBox, box_corners, cast_box, matched_distances

__all__ = ["image_metrics", "truth_metrics", "truth_scale", "camera_corners"]


def image_metrics(box: RoomBox, camera: Camera, classes: np.ndarray, depth: np.ndarray, scale: float) -> dict:
    labels, box_depth = cast_box(box, camera)
    room = classes >= 0
    ious = {}
    for i, name in enumerate(BOX_CLASSES):
        rendered, target = room & (labels == i), classes == i
        union = (rendered | target).sum()
        ious[name] = round(float((rendered & target).sum() / union), 4) if union else None
    has_depth = room & (depth > 0)
    error = float(np.abs(box_depth[has_depth] - depth[has_depth]).mean()) if has_depth.any() else None
    return {
        "mask_iou": ious,
        "depth_error": None if error is None else round(error, 5),
        "depth_error_relative": None if error is None else round(error / scale, 5),
    }


def camera_corners(box: RoomBox, camera: Camera) -> np.ndarray:
    return box_corners(box) @ np.asarray(camera.R).T + np.asarray(camera.t)


def truth_scale(classes: np.ndarray, depth: np.ndarray, truth_box: RoomBox, truth_camera: Camera) -> float:
    """The factor from the depth's units to the truth's: the median ratio of the truth box's depth
    to the photo's over the room's pixels (1 for a metric depth; a monocular estimate's scale is
    unknown, and is aligned so in depth evaluations)."""
    truth_depth = cast_box(truth_box, truth_camera)[1]
    both = (classes >= 0) & (depth > 0) & (truth_depth > 0)
    return float(np.median(truth_depth[both] / depth[both])) if both.any() else 1.0


def truth_metrics(box: RoomBox, camera: Camera, truth_box: RoomBox, truth_camera: Camera, scale: float = 1.0) -> dict:
    """Corner and size errors in the truth's units, the estimate first multiplied by ``scale``."""
    estimate, truth = scale * camera_corners(box, camera), camera_corners(truth_box, truth_camera)
    uv = project_points(truth_camera, box_corners(truth_box))
    seen = np.isfinite(uv).all(axis=1)
    seen &= (uv[:, 0] >= 0) & (uv[:, 0] <= truth_camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= truth_camera.height)
    matched = matched_distances(estimate, truth)
    return {
        "corner_error": round(float(matched.mean()), 5),
        "visible_corner_error": round(float(matched[seen].mean()), 5) if seen.any() else None,
        "visible_corners": int(seen.sum()),
        "size_error": [round(float(v), 5) for v in scale * np.sort(box.size[[0, 2]]) - np.sort(truth_box.size[[0, 2]])]
        + [round(float(scale * box.size[1] - truth_box.size[1]), 5)],
    }
