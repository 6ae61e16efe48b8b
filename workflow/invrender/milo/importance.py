"""The captured images projected onto the atlas (section 3.5): each texel's observed radiance.

MILO samples normal materials' texels by this brightness in its texture importance sampling; here
it also starts the material assignment. "For the conservation of energy, the brightest area
should belong to the light-emitting object" (section 3.3): texels observed far brighter than any
lit wall start as emitters, and training revises the guess. Without it the network starts
from a room with no light in it, every texel is pushed towards emitting at once, and the emitting
material settles as a dim glow over everything (measured in docs/milo.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..render.renderer import Renderer, pixel_requests
from ..render.scene_buffers import LUMINANCE
from ..scene.atlas import AtlasTexels
from ..scene.cameras import project_points
from ..scene.types import Camera

DEPTH_TOLERANCE = 0.01  # a texel is seen when it lies within 1 % of the depth the camera sees


@dataclass
class TexelPixels:
    """Which pixel of which view sees each covered texel (nearest pixel, occlusion by the
    rendered depth): computed once, it projects any set of images of those views onto the atlas."""

    atlas: AtlasTexels
    rows: np.ndarray  # the covered texels' atlas rows and columns
    cols: np.ndarray
    seen: list[tuple[np.ndarray, np.ndarray]]  # per view: (texel index, flat pixel index)

    @classmethod
    def build(cls, atlas: AtlasTexels, renderer: Renderer, cameras: list[Camera]) -> TexelPixels:
        rows, cols = np.nonzero(atlas.mask)
        points = atlas.position[rows, cols].astype(np.float64)
        seen = []
        for index, camera in enumerate(cameras):
            aovs = renderer.aovs(cameras, pixel_requests(camera, index))
            depth = aovs["depth"].reshape(camera.height, camera.width)
            pixels = project_points(camera, points)
            inside = np.all(np.isfinite(pixels), axis=1)
            inside[inside] &= (pixels[inside] >= 0).all(1) & (pixels[inside, 0] < camera.width)
            inside[inside] &= pixels[inside, 1] < camera.height
            x = np.floor(pixels[inside, 0]).astype(int)
            y = np.floor(pixels[inside, 1]).astype(int)
            z = (points[inside] @ np.asarray(camera.R).T + camera.t)[:, 2]
            keep = z <= depth[y, x] * (1 + DEPTH_TOLERANCE) + 1e-4  # not behind what the camera sees
            seen.append((np.flatnonzero(inside)[keep], y[keep] * camera.width + x[keep]))
        return cls(atlas, rows, cols, seen)

    def project(self, images) -> tuple[np.ndarray, np.ndarray]:
        """(radiance (H, W, 3), views (H, W)): each texel's median over the views that see it of
        `images` (one (height, width, 3) array per view), and how many views see it. The median,
        not the mean: a view whose pixel mixes the texel with what lies beside it (an edge, a
        lamp's rim, a highlight) does not move it."""
        texels = np.concatenate([t for t, _ in self.seen])
        values = np.concatenate([np.asarray(im).reshape(-1, 3)[p] for (_, p), im in zip(self.seen, images)])
        count = np.bincount(texels, minlength=len(self.rows))
        radiance = np.zeros((*self.atlas.shape, 3), np.float32)
        radiance[self.rows, self.cols] = per_group_median(texels, values, count)
        views = np.zeros(self.atlas.shape, np.int32)
        views[self.rows, self.cols] = count
        return radiance, views


def per_group_median(groups: np.ndarray, values: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(G, C): per group g in 0..G-1 the median of the `values` (N, C) whose `groups` (N,) is g
    (the mean of the two middle ones for an even count; 0 for an empty group), by one sort per
    channel."""
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    low, high = start + (count - 1) // 2, start + count // 2
    out = np.zeros((len(count), values.shape[1]))
    seen = count > 0
    for c in range(values.shape[1]):
        ordered = values[np.lexsort((values[:, c], groups)), c]
        out[seen, c] = 0.5 * (ordered[low[seen]] + ordered[high[seen]])
    return out


def emitting_start(radiance: np.ndarray, views: np.ndarray, emission: float, fraction: float) -> np.ndarray:
    """(H, W) bool: texels seen brighter than `fraction` of the capture's brightest radiance."""
    return (views > 0) & ((radiance @ LUMINANCE.astype(np.float32)) > fraction * emission)
