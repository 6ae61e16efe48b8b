"""What a user looks at: the recovered mesh's outline at every pose, over the photograph."""

from __future__ import annotations

import cv2
import numpy as np

from ..scene.images import linear_to_srgb
from ..scene.types import Mesh
from .refine import silhouette

__all__ = ["write_overlay"]


def write_overlay(path, photo: np.ndarray, mesh: Mesh, K: np.ndarray, poses: dict) -> None:
    """The photo (sRGB) with each posed mesh's outline (refine.silhouette, the rasteriser the
    refinement compares with the masks) drawn and numbered."""
    height, width = photo.shape[:2]
    canvas = np.clip(linear_to_srgb(np.clip(photo, 0, None) / max(np.percentile(photo, 99), 1e-6)), 0, 1) * 255
    canvas = np.ascontiguousarray(canvas.astype(np.uint8)[..., ::-1])
    thickness = max(1, round(max(photo.shape[:2]) / 400))
    for instance_id, T in sorted(poses.items()):
        mask = (silhouette(mesh, K, T, (0, 0, width, height), supersample=1) > 0.5).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(canvas, contours, -1, (0, 255, 0), thickness)
        if contours:
            x, y, w, h = cv2.boundingRect(np.concatenate(contours))
            cv2.putText(
                canvas,
                str(instance_id),
                (x, y + h // 2),
                cv2.FONT_HERSHEY_SIMPLEX,
                thickness * 0.5,
                (255, 255, 0),
                thickness,
            )
    cv2.imwrite(str(path), canvas)
