"""A capture's images: one image per camera, named as the camera's image, in linear RGB.

EXR is read as it is; PNG/JPEG are decoded from sRGB to linear (scene/images.py). Every stage
that compares renders with the photographs reads them through here, so the naming rule and the
size check are written once.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .images import read_image
from .types import Camera, SceneError


def read_view(images_dir, camera: Camera) -> np.ndarray:
    """The captured linear RGB image of one camera, (H, W, 3) float32, checked against its size."""
    path = Path(images_dir) / camera.name
    if not path.exists():
        raise SceneError(path, f"image of camera {camera.name}", "an image for every camera of the model")
    image = read_image(path)
    if image.shape[:2] != (camera.height, camera.width):
        raise SceneError(
            path,
            "size",
            f"{camera.width} x {camera.height} as its camera says, got {image.shape[1]} x {image.shape[0]}",
        )
    return image[..., :3] if image.shape[2] >= 3 else np.repeat(image, 3, axis=2)


def pixel_targets(images_dir, cameras: list[Camera], requests: np.ndarray) -> np.ndarray:
    """The captured radiance of each requested pixel: int4 requests (camera, x, y, ray id)."""
    images = [read_view(images_dir, camera) for camera in cameras]
    return np.stack([images[c][y, x] for c, x, y, _ in requests]).astype(np.float32)
