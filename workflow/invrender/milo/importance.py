"""The captured images projected onto the atlas (section 3.5): each texel's observed radiance.

MILO samples normal materials' texels by this brightness in its texture importance sampling; here
it also starts the material assignment. "For the conservation of energy, the brightest area
should belong to the light-emitting object" (section 3.3): texels observed far brighter than any
lit wall start as emitters, and training revises the guess. Without it the network starts
from a room with no light in it, every texel is pushed towards emitting at once, and the emitting
material settles as a dim glow over everything (measured in docs/milo.md).
"""

from __future__ import annotations

import numpy as np

from ..render.renderer import Renderer, pixel_requests
from ..render.scene_buffers import LUMINANCE
from ..scene.atlas import AtlasTexels
from ..scene.cameras import project_points
from ..scene.types import Camera

DEPTH_TOLERANCE = 0.01  # a texel is seen when it lies within 1 % of the depth the camera sees


def observed_radiance(atlas: AtlasTexels, renderer: Renderer, cameras: list[Camera], images) -> tuple:
    """(radiance (H, W, 3), views (H, W)): each texel's mean captured radiance over the views that
    see it (nearest pixel; occlusion by the rendered depth), and how many views see it."""
    h, w = atlas.shape
    rows, cols = np.nonzero(atlas.mask)
    points = atlas.position[rows, cols].astype(np.float64)
    total = np.zeros((len(rows), 3))
    count = np.zeros(len(rows))
    for index, (camera, image) in enumerate(zip(cameras, images)):
        depth = renderer.aovs(cameras, pixel_requests(camera, index))["depth"].reshape(camera.height, camera.width)
        pixels = project_points(camera, points)
        inside = np.all(np.isfinite(pixels), axis=1)
        inside[inside] &= (pixels[inside] >= 0).all(1) & (pixels[inside, 0] < camera.width)
        inside[inside] &= pixels[inside, 1] < camera.height
        x = np.floor(pixels[inside, 0]).astype(int)
        y = np.floor(pixels[inside, 1]).astype(int)
        z = (points[inside] @ np.asarray(camera.R).T + camera.t)[:, 2]
        keep = z <= depth[y, x] * (1 + DEPTH_TOLERANCE) + 1e-4  # not behind what the camera sees
        seen = np.flatnonzero(inside)[keep]
        total[seen] += image[y[keep], x[keep]]
        count[seen] += 1
    radiance = np.zeros((h, w, 3), np.float32)
    views = np.zeros((h, w), np.int32)
    radiance[rows, cols] = total / np.maximum(count, 1)[:, None]
    views[rows, cols] = count
    return radiance, views


def emitting_start(radiance: np.ndarray, views: np.ndarray, emission: float, fraction: float) -> np.ndarray:
    """(H, W) bool: texels seen brighter than `fraction` of the capture's brightest radiance."""
    return (views > 0) & ((radiance @ LUMINANCE.astype(np.float32)) > fraction * emission)
