"""Retrieval of a library material for a photo crop, and the transform search (PSDR-Room
section 4.4, "Material initialization and search").

The paper ranks its materials by CLIP similarity of thumbnails, then samples the chosen one at
scales 0.5-8 and rotations -45, 0, 45, 90 and keeps the transform of least Gram loss. No CLIP
here: both steps use one texture descriptor, the Gram matrices (gram.py) of the crop's
*structure*, its luminance with the mean removed and the contrast normalised, so that a preset's
colours and contrast (which the fit then changes) do not decide which pattern it is. A preset's
distance to the crop is its least over the transform grid, so retrieval and transform search
are one search; the plain preset competes like the others (the paper's "if the Gram matrix loss
of a homogeneous material is better than any of the texture transforms ... treat it as
homogeneous").

A crop's width is one UV unit: a transform's scale is the number of pattern repetitions across
it. Crops are area-downsampled to at most `CROP_SIZE` pixels before anything else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..render.bsdf import REC709
from .base import DTYPE, Transform, single_thread
from .gram import descriptor, load_network
from .library import PRESETS, Preset

__all__ = [
    "SCALES",
    "ROTATIONS",
    "CROP_SIZE",
    "Match",
    "prepare_crop",
    "remove_shading",
    "structure",
    "transform_grid",
    "retrieve",
]

# The paper's ranges: scales 0.5-8 (here a geometric grid, two steps per octave, so the nearest
# grid scale is within a factor 2^(1/4) = 1.19 of any scale in range), rotations -45, 0, 45, 90.
SCALES = tuple(0.5 * 2 ** (k / 2) for k in range(9))
ROTATIONS = (-45.0, 0.0, 45.0, 90.0)
CROP_SIZE = 64
# Contrast below this fraction of the mean luminance is noise, not texture: a plain crop is not
# amplified into one (its structure stays nearly flat, as the plain preset's). At 0.05, pixel
# noise of 0.01 on a dark plain crop (mean 0.3) was amplified into a pattern nearer a fine
# checker than flat (measured); at 0.1 it stays flat.
_CONTRAST_FLOOR = 0.1
# The structure image's contrast: the Gram network's reference (gram._REFERENCE_STD).
_STRUCTURE_STD = 0.1


@dataclass(frozen=True)
class Match:
    preset: Preset
    transform: Transform
    distance: float  # squared descriptor distance (the Gram loss of the structure images)


def prepare_crop(crop, max_size: int = CROP_SIZE) -> torch.Tensor:
    """A crop (H, W, 3) linear RGB (numpy or torch) as a float tensor, area-downsampled by an
    integer factor so that neither side exceeds max_size."""
    crop = torch.as_tensor(np.asarray(crop, np.float32) if not torch.is_tensor(crop) else crop, dtype=DTYPE)
    if crop.dim() != 3 or crop.shape[2] != 3 or min(crop.shape[:2]) < 8:
        raise ValueError(f"a crop must be (H, W, 3) with sides of at least 8 pixels, got {tuple(crop.shape)}")
    factor = math.ceil(max(crop.shape[:2]) / max_size)
    if factor > 1:
        h, w = (crop.shape[0] // factor) * factor, (crop.shape[1] // factor) * factor
        crop = torch.nn.functional.avg_pool2d(crop[:h, :w].permute(2, 0, 1)[None], factor)[0].permute(1, 2, 0)
    return crop


def remove_shading(images: torch.Tensor) -> torch.Tensor:
    """Images (B, H, W, 3) divided by the least-squares plane a + b x + c y through their
    luminance, times its mean: a crop of a planar surface is lit unevenly (a lamp's falloff, a
    shadow's edge), and that gradient is the light's, not the texture's. A pattern repeating
    within the crop has almost no linear trend, so it stays."""
    b, h, w, _ = images.shape
    lum = images @ torch.as_tensor(REC709, dtype=images.dtype)
    y, x = torch.meshgrid(
        torch.linspace(-1, 1, h, dtype=images.dtype), torch.linspace(-1, 1, w, dtype=images.dtype), indexing="ij"
    )
    # 1, x and y are orthogonal on the symmetric grid: each coefficient is a projection.
    mean = lum.mean(dim=(1, 2), keepdim=True)
    slope_x = (lum * x).sum(dim=(1, 2), keepdim=True) / (x * x).sum()
    slope_y = (lum * y).sum(dim=(1, 2), keepdim=True) / (y * y).sum()
    plane = mean + slope_x * x + slope_y * y
    ratio = mean / torch.clamp(plane, min=1e-3 + 0.1 * mean.abs())
    return images * ratio[..., None]


def structure(images: torch.Tensor) -> torch.Tensor:
    """Images (B, H, W, 3) -> (B, 3, H, W): luminance with the shading gradient and the mean
    removed, contrast normalised to `_STRUCTURE_STD` (contrasts under the floor are not
    amplified), grey."""
    lum = remove_shading(images) @ torch.as_tensor(REC709, dtype=images.dtype)
    mean = lum.mean(dim=(1, 2), keepdim=True)
    std = lum.std(dim=(1, 2), keepdim=True)
    scale = _STRUCTURE_STD / torch.maximum(std, _CONTRAST_FLOOR * mean + 1e-6)
    grey = 0.5 + (lum - mean) * scale
    return grey[:, None].expand(-1, 3, -1, -1)


# The library's crops start here in material space: every type has pattern edges at integer
# coordinates (checker squares, tile rows, wood rings, weave cells), so a crop from 0.75 shows
# one even at scale 0.5, where a crop from 0 would show half a checker square, flat as plain
# (measured: a plain crop then came out a checker at scale 0.5).
LIBRARY_OFFSET = (0.75, 0.75)


def transform_grid(scales=SCALES, rotations=ROTATIONS) -> list[Transform]:
    return [Transform(scale=s, rotation_deg=r, offset=LIBRARY_OFFSET) for s in scales for r in rotations]


_LIBRARY_CACHE: dict = {}


def _library_descriptors(presets, net, height: int, width: int, transforms) -> torch.Tensor:
    """(presets, transforms, D) structure descriptors of every preset under every transform,
    kept per crop size and network (they do not depend on the crop)."""
    # the network itself, not its id: a freed network's id can be reused by another's
    key = (tuple(p.name for p in presets), net, height, width, tuple(transforms))
    if key not in _LIBRARY_CACHE:
        rows = []
        with torch.no_grad():
            for p in presets:
                images = torch.stack([p.type.image(height, p.params(), t, width) for t in transforms])
                rows.append(descriptor(net, structure(images)))
        _LIBRARY_CACHE[key] = torch.stack(rows)
    return _LIBRARY_CACHE[key]


def retrieve(crop, presets=PRESETS, net=None, transforms=None) -> list[Match]:
    """Every preset with its best transform for the crop, nearest first."""
    net = net or default_network()
    transforms = transforms or transform_grid()
    with single_thread(), torch.no_grad():
        crop = prepare_crop(crop)
        target = descriptor(net, structure(crop[None]))[0]
        library = _library_descriptors(presets, net, crop.shape[0], crop.shape[1], transforms)
        distance = ((library - target) ** 2).sum(dim=2)  # (presets, transforms)
        best = distance.argmin(dim=1)
    matches = [Match(p, transforms[int(best[i])], float(distance[i, best[i]])) for i, p in enumerate(presets)]
    return sorted(matches, key=lambda m: m.distance)


_DEFAULT = {}


def default_network():
    """The seeded random network, built once per process."""
    if "net" not in _DEFAULT:
        _DEFAULT["net"] = load_network()
    return _DEFAULT["net"]
