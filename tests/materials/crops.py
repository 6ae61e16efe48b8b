"""Synthetic photo crops made from the library itself, with known parameters and transforms:
the truth that retrieval and the fit are measured against (tests and measure.py)."""

from __future__ import annotations

import math

import numpy as np
import torch

from invrender.materials.base import Transform
from invrender.materials.retrieval import ROTATIONS

# Scales drawn log-uniformly in this range: at 0.5 a 64-pixel crop shows half a period, too
# little of most patterns to tell them apart, so the draws start a little above.
SCALE_RANGE = (0.7, 6.0)
SHADING = 0.1  # the lighting gradient's amplitude across the crop (a fraction of the mean)
NOISE = 0.01  # Gaussian pixel noise, linear units
JITTER_DEG = 5.0  # rotations are the grid's plus up to this much


def perturbed_params(preset, rng, amount: float = 0.15) -> dict[str, torch.Tensor]:
    """The preset's parameters with each texture parameter moved by up to `amount` of its range
    (each colour channel on its own), kept inside 5-95 % of it."""
    params = preset.params()
    for p in preset.type.params:
        if p.texture:
            unit = (params[p.name] - p.low) / (p.high - p.low)
            step = torch.as_tensor(rng.uniform(-amount, amount, tuple(unit.shape)), dtype=unit.dtype)
            params[p.name] = p.low + (p.high - p.low) * torch.clamp(unit + step, 0.05, 0.95)
    return params


def random_transform(rng, scale_range=SCALE_RANGE) -> Transform:
    lo, hi = scale_range
    scale = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    rotation = float(rng.choice(ROTATIONS) + rng.uniform(-JITTER_DEG, JITTER_DEG))
    return Transform(scale, rotation, tuple(float(o) for o in rng.uniform(0, 10, 2)))


def synthetic_crop(preset, rng, size: int = 64, perturb: bool = True, scale_range=SCALE_RANGE):
    """(crop (size, size, 3) float32, true params, true transform): the material's kd under a
    random transform, times a linear lighting gradient, plus pixel noise."""
    truth = perturbed_params(preset, rng) if perturb else preset.params()
    transform = random_transform(rng, scale_range)
    with torch.no_grad():
        kd = preset.type.image(size, truth, transform).numpy()
    ramp = np.linspace(-1, 1, size)
    direction = rng.uniform(0, 2 * math.pi)
    shading = 1 + SHADING * (math.cos(direction) * ramp[None, :] + math.sin(direction) * ramp[:, None])
    crop = kd * shading[..., None] + rng.normal(0, NOISE, kd.shape)
    return crop.astype(np.float32), truth, transform


def rotation_error(found: float, truth: float, symmetry: float) -> float:
    """Degrees between two rotations of a pattern that repeats every `symmetry` degrees."""
    d = (found - truth) % symmetry
    return min(d, symmetry - d)
