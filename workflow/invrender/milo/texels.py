"""What MILO-Net reads: the atlas texels' 3D points and normals, and the sky's directions.

Texels outside every chart but next to one (the atlas padding) are read by the renderer at chart
edges, so they are evaluated too, at the point of their nearest covered neighbour (dilation).
Positions are normalised to [-1, 1] with one scale for all axes (section 3.4), so the encoding's
frequencies mean the same length along every wall.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..scene.atlas import AtlasTexels, dilate
from ..scene.cubemap import texel_directions

PADDING_TEXELS = 3  # rings of padding texels evaluated beside the charts


@dataclass
class Texels:
    """The texels the network is evaluated at: their (row, col), inputs, and the atlas shape."""

    rows: np.ndarray
    cols: np.ndarray
    positions: torch.Tensor  # (n, 3) in [-1, 1]
    normals: torch.Tensor  # (n, 3) unit
    shape: tuple[int, int]
    mask: np.ndarray  # (H, W) the covered texels
    center: np.ndarray
    scale: float

    def __len__(self) -> int:
        return len(self.rows)

    @classmethod
    def from_atlas(cls, atlas: AtlasTexels) -> Texels:
        mask = atlas.mask
        points = atlas.position[mask].astype(np.float64)
        low, high = points.min(0), points.max(0)
        center, scale = (low + high) / 2, float(max((high - low).max() / 2, 1e-9))
        position, grown = dilate(atlas.position, mask, PADDING_TEXELS)
        normal, _ = dilate(atlas.normal, mask, PADDING_TEXELS)
        normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
        rows, cols = np.nonzero(grown)
        normalised = np.clip((position[rows, cols] - center) / scale, -1, 1)
        return cls(
            rows=rows,
            cols=cols,
            positions=torch.from_numpy(normalised.astype(np.float32)),
            normals=torch.from_numpy(normal[rows, cols].astype(np.float32)),
            shape=mask.shape,
            mask=mask,
            center=center,
            scale=scale,
        )

    def scatter(self, values: np.ndarray, channels: int, background=0.0) -> np.ndarray:
        """(H, W, channels) with `values` (n, channels) at the texels and `background` (a value
        per channel) elsewhere."""
        out = np.empty((*self.shape, channels), np.float32)
        out[...] = background
        out[self.rows, self.cols] = values
        return out

    def gather(self, atlas: np.ndarray) -> np.ndarray:
        """The texels' rows of an (H, W, C) array."""
        return atlas[self.rows, self.cols]

    def gather_grown(self, atlas: np.ndarray) -> np.ndarray:
        """The texels' rows of an (H, W, ...) array given on the covered texels: a padding texel
        takes its nearest covered neighbour's value, as its position does (from_atlas)."""
        grown, _ = dilate(np.asarray(atlas), self.mask, PADDING_TEXELS)
        return grown[self.rows, self.cols]


def sky_directions(n: int) -> torch.Tensor:
    """(6 N N, 3) unit directions of the kg cube map's texels, in its layout."""
    return torch.from_numpy(texel_directions(n).reshape(-1, 3).astype(np.float32))
