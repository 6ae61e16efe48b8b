"""The fit of a material's continuous parameters to a photo crop: Adam under the Gram loss plus
the mean colour (the crop terms of PSDR-Room Eq. 4), with the transform from the search fixed.

Only the parameters that change kd (`Param.texture`) move: a crop of a flat surface seen once
shows albedo times light, not roughness or specular (those need the renderer: the joint stage).
`gain` is the light: the crop is compared with gain * kd, where gain (a number or RGB) is the
radiance a unit albedo sends back (from a unit-albedo render, or 1 for an albedo crop).
Parameters move in logit coordinates of their bounds, so every step stays inside them. The
transform's scale is refined with them, within the search grid's cell (a factor 2^(1/4) either
way, through a tanh): the grid leaves it up to that far off, and a pattern at the wrong scale
cannot match a crop's Gram matrices whatever its colours; unbounded, the Gram loss's local minima
pulled it off by octaves (measured: a wood crop at scale 3.4 went from 2.8 to 0.9). Rotation
and offset stay: the Gram loss does not see the offset, and the rotation's grid is the paper's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import torch

from .base import DTYPE, Material, Transform, from_unit, single_thread, to_unit
from .gram import gram_loss, gram_matrices
from .retrieval import default_network, prepare_crop, remove_shading

__all__ = ["FitResult", "fit"]

# The mean colour term's weight against the Gram loss (summed over layers, about 1 for a
# textured crop against a flat one): a colour error of 0.01 costs as much as a whole texture's
# Gram loss, so the mean is nearly a constraint and the Gram matrices shape the pattern around
# it. At 10, a transform a few degrees or percent off the crop's let the Gram loss pull the
# colours away from the crop's mean (measured: a denim warp 0.024 off in red).
COLOUR_WEIGHT = 100.0
# Half the search grid's step in log scale (retrieval.SCALES: two steps per octave).
SCALE_STEP = math.log(2.0) / 4
_EDGE = 1e-3  # parameters start at least this far (in [0, 1] units) from their bounds


@dataclass
class FitResult:
    params: dict[str, torch.Tensor]  # every parameter, detached
    transform: Transform  # the search's, its scale refined
    losses: list[float]  # the total loss per step
    seconds: float

    def values(self) -> dict:
        return {k: v.tolist() for k, v in self.params.items()}


def crop_loss(net, image, target_grams, target_mean, colour_weight=COLOUR_WEIGHT):
    """Gram loss + colour_weight * L1 of the mean colours, of one image (H, W, 3)."""
    gram = gram_loss(net, image.permute(2, 0, 1)[None], target_grams)[0]
    return gram + colour_weight * (image.mean(dim=(0, 1)) - target_mean).abs().sum()


def fit(
    material: Material,
    params: dict,
    transform: Transform,
    crop,
    steps: int = 80,
    lr: float = 0.05,
    gain=1.0,
    net=None,
    colour_weight: float = COLOUR_WEIGHT,
    fit_scale: bool = True,
) -> FitResult:
    """Adam on `material`'s texture parameters from `params` so that gain * kd under
    `transform` matches the crop (H, W, 3, linear RGB, its width one UV unit)."""
    net = net or default_network()
    start = time.perf_counter()
    with single_thread():
        target = remove_shading(prepare_crop(crop)[None])[0]
        h, w = target.shape[:2]
        gain = torch.as_tensor(gain, dtype=DTYPE)
        with torch.no_grad():
            target_grams = gram_matrices(net, target)
            target_mean = target.mean(dim=(0, 1))
        full = material.complete(params)
        unit = to_unit(material, {k: v.detach() for k, v in full.items()})
        free = [p.name for p in material.params if p.texture]
        logits = {k: torch.logit(unit[k].clamp(_EDGE, 1 - _EDGE)).requires_grad_(True) for k in free}
        scale_logit = torch.zeros((), dtype=DTYPE, requires_grad=fit_scale)
        optimizer = torch.optim.Adam(list(logits.values()) + ([scale_logit] if fit_scale else []), lr=lr)

        def scale():
            return float(transform.scale) * torch.exp(SCALE_STEP * torch.tanh(scale_logit))

        losses = []

        def current():
            u = dict(unit)
            u.update({k: torch.sigmoid(z) for k, z in logits.items()})
            return from_unit(material, u)

        for _ in range(steps):
            optimizer.zero_grad()
            scaled = Transform(scale(), transform.rotation_deg, transform.offset)
            image = gain * material.image(h, current(), scaled, w)
            loss = crop_loss(net, image, target_grams, target_mean, colour_weight)
            loss.backward()
            optimizer.step()
            losses.append(loss.item())
        with torch.no_grad():
            result = {k: v.detach() for k, v in current().items()}
    fitted = Transform(float(scale().detach()), transform.rotation_deg, transform.offset)
    return FitResult(result, fitted, losses, time.perf_counter() - start)
