"""One crop per instance: the instance's pixels at a fixed size, and the exact map back to the
full image, so that keypoints found in a crop go to COLMAP in the real camera's pixels.

COLMAP rejects a crop-sized camera whose principal point lies outside the crop (FACTS.md), and a
resized crop would need its own intrinsics: declaring every crop as the full-frame real camera,
with its keypoints moved back by ``full = crop / scale + offset``, keeps one camera and the same
geometry. Pixel coordinates are COLMAP's: pixel (x, y) covers [x, x + 1) x [y, y + 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Crop", "make_crop", "make_crops", "instance_boxes"]


@dataclass
class Crop:
    instance_id: int
    image: np.ndarray  # (S, S, 3) float32 linear RGB; zero outside the mask if masked
    mask: np.ndarray  # (S, S) bool: the instance's own pixels
    offset: np.ndarray  # (2,) float64: full-image position of the crop's corner (0, 0)
    scale: float  # crop pixels per full-image pixel

    def to_full(self, xy) -> np.ndarray:
        """Crop pixel coordinates (N, 2) -> full-image pixel coordinates."""
        return np.asarray(xy, np.float64) / self.scale + self.offset

    def to_crop(self, xy) -> np.ndarray:
        return (np.asarray(xy, np.float64) - self.offset) * self.scale


def instance_boxes(ids: np.ndarray) -> dict[int, tuple[int, int, int, int]]:
    """{id: (x0, y0, x1, y1)}, x1 and y1 exclusive, for every nonzero id of the id image."""
    boxes = {}
    for k, (ys, xs) in enumerate(_slices(ids)):
        if ys is not None:
            boxes[k] = (xs.start, ys.start, xs.stop, ys.stop)
    return boxes


def _slices(ids):
    from scipy import ndimage

    found = ndimage.find_objects(np.asarray(ids, np.int64))
    return [(None, None)] + [(s[0], s[1]) if s is not None else (None, None) for s in found]


def _square(box, pad: float) -> tuple[np.ndarray, float]:
    """The square window around a box, `pad` of its longer side added on every side: (corner,
    side) in full-image pixels."""
    x0, y0, x1, y1 = box
    side = max(x1 - x0, y1 - y0) * (1 + 2 * pad)
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2], np.float64)
    return centre - side / 2, side


def _warp(array, offset, scale: float, size: int, interpolation) -> np.ndarray:
    """array sampled at crop pixel centres: crop (x + 0.5) / scale + offset in COLMAP
    coordinates is array index (x + 0.5) / scale + offset - 0.5."""
    shift = 0.5 / scale + offset - 0.5
    M = np.array([[1 / scale, 0, shift[0]], [0, 1 / scale, shift[1]]], np.float64)
    flags = interpolation | cv2.WARP_INVERSE_MAP
    return cv2.warpAffine(array, M, (size, size), flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def make_crop(image, ids, instance_id: int, box, size: int = 256, pad: float = 0.1, masked: bool = True) -> Crop:
    """The crop of one instance. Downscaling blurs first (Gaussian of 0.5 output pixels) so that
    the bilinear sampling does not alias fine print into false features."""
    offset, side = _square(box, pad)
    scale = size / side
    source = np.asarray(image, np.float32)
    if scale < 1:
        sigma = 0.5 / scale
        source = cv2.GaussianBlur(source, (0, 0), sigmaX=sigma, sigmaY=sigma)
    own = (np.asarray(ids) == instance_id).astype(np.float32)
    pixels = _warp(source, offset, scale, size, cv2.INTER_LINEAR)
    mask = _warp(own, offset, scale, size, cv2.INTER_LINEAR) > 0.5
    if masked:
        pixels = pixels * mask[..., None]
    return Crop(instance_id, pixels.astype(np.float32), mask, offset, float(scale))


def make_crops(image, ids, size: int = 256, pad: float = 0.1, masked: bool = True) -> list[Crop]:
    """One crop per instance of the id image, in id order."""
    boxes = instance_boxes(ids)
    return [make_crop(image, ids, k, box, size, pad, masked) for k, box in sorted(boxes.items())]
