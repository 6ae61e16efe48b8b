"""Per-instance crops of a duplicates image: a fixed-size square around each instance, its
mask, and the map back to the full image's pixels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Crop"]


@dataclass
class Crop:
    instance_id: int
    image: np.ndarray  # (S, S, 3) float32 linear RGB; outside the mask zero if masked
    mask: np.ndarray  # (S, S) bool: the instance's own pixels
    offset: np.ndarray  # (2,) float64: full-image position of the crop's corner (0, 0)
    scale: float  # crop pixels per full-image pixel
    # full-image xy = crop xy / scale + offset      (both in COLMAP pixel coordinates)
