"""What a user looks at: the recovered mesh's outline at every pose, over the photograph."""

from __future__ import annotations

import cv2
import numpy as np

from ..scene.images import linear_to_srgb
from ..scene.types import Mesh

__all__ = ["write_overlay", "silhouette"]

SUBPIXEL = 4  # fillPoly's fixed-point bits: vertices at 1/16 pixel


def silhouette(mesh: Mesh, K: np.ndarray, T_cam_from_obj: np.ndarray, shape) -> np.ndarray:
    """(H, W) bool: pixels whose centre the posed mesh covers (triangles in front of the camera)."""
    p = mesh.positions.astype(np.float64) @ T_cam_from_obj[:3, :3].T + T_cam_from_obj[:3, 3]
    front = p[:, 2] > 1e-9
    uv = (p @ K.T)[:, :2] / np.where(front, p[:, 2], 1.0)[:, None]
    faces = mesh.faces[front[mesh.faces].all(axis=1)]
    # COLMAP's pixel x covers [x, x + 1): fillPoly's pixel x is centred on x, hence the -0.5
    points = np.round((uv[faces] - 0.5) * (1 << SUBPIXEL)).astype(np.int32)
    out = np.zeros(shape, np.uint8)
    cv2.fillPoly(out, list(points), 1, lineType=cv2.LINE_8, shift=SUBPIXEL)
    return out.astype(bool)


def write_overlay(path, photo: np.ndarray, mesh: Mesh, K: np.ndarray, poses: dict) -> None:
    """The photo (sRGB) with each posed mesh's outline drawn and numbered."""
    canvas = np.clip(linear_to_srgb(np.clip(photo, 0, None) / max(np.percentile(photo, 99), 1e-6)), 0, 1) * 255
    canvas = np.ascontiguousarray(canvas.astype(np.uint8)[..., ::-1])
    thickness = max(1, round(max(photo.shape[:2]) / 400))
    for instance_id, T in sorted(poses.items()):
        mask = silhouette(mesh, K, T, photo.shape[:2]).astype(np.uint8)
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
