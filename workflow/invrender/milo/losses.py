"""The losses of Eq. 11, each a mean so that the weights do not depend on the batch size or the
atlas resolution (the paper's sums tie them to both, section 3.5).

The image loss (Eq. 5) is evaluated on the renderer's estimates and its derivative with respect to
each ray's radiance is handed to the adjoint; the regularisers are torch expressions of the
network's outputs on a random share of the texels.
"""

from __future__ import annotations

import numpy as np
import torch

from ..render.adjoint import GRAD_CHANNELS
from ..render.scene_buffers import LUMINANCE
from .network import LOWER, UPPER

IMAGE_LOSSES = ("relative_mse", "mse", "norm")


def image_loss(radiance: np.ndarray, target: np.ndarray, kind: str = "relative_mse", epsilon: float = 0.1):
    """The image loss over the batch (a mean over rays) and dLoss/dL_j (n, 3).

    "norm" is Eq. 5 as written: || L_j - T_j ||_2. Its derivative, (L - T) / ||L - T||, is a
    sign: with few samples per ray it matches the estimates' median to the photographs, not their
    mean, and the median of light that arrives by rare paths (a small lamp seen by reflection) is
    far below its mean; training then explains the room by omnidirectional emission, which has no
    variance (measured in docs/milo.md). The squared norms are minimised by the mean when the
    adjoint traces other samples than the forward (render/adjoint.backward_seed): "mse", and
    "relative_mse", each ray weighted by 1 / (luminance(T_j) + epsilon), the weight of photon noise
    (its variance grows as the radiance), so that lamps and the sun neither outweigh the walls (as
    in "mse") nor vanish beside them (as with a squared weight); the weight depends on the
    photograph only, so the gradient stays unbiased.
    """
    residual = radiance.astype(np.float64) - target
    if kind == "norm":
        norm = np.linalg.norm(residual, axis=1, keepdims=True)
        adjoint = np.where(norm > 0, residual / np.where(norm > 0, norm, 1.0), 0.0)
        return float(norm.mean()), adjoint / len(residual)
    weight = np.ones((len(residual), 1))
    if kind == "relative_mse":
        weight = 1.0 / (target @ LUMINANCE + epsilon)[:, None]
    elif kind != "mse":
        raise ValueError(f"image_loss: kind: expected one of {IMAGE_LOSSES}, got {kind!r}")
    squared = (weight * residual**2).sum(axis=1)
    return float(squared.mean()), 2.0 * weight * residual / len(residual)


def category_loss(probabilities: torch.Tensor) -> torch.Tensor:
    """Eq. 8: each texel one material (mean of -max_i P_i)."""
    return -probabilities.max(-1).values.mean()


def texture_loss(detail: torch.Tensor) -> torch.Tensor:
    """Eq. 10: the detail texture's L1 norm, so the template explains what it can."""
    return detail.abs().sum(-1).mean()


def value_loss(raw: torch.Tensor) -> torch.Tensor:
    """Squared distance outside the valid ranges, and the energy bound kd + ks <= 1 per channel."""
    below = torch.relu(LOWER.to(raw) - raw)
    above = torch.relu(raw - UPPER.to(raw))
    energy = torch.relu(raw[:, GRAD_CHANNELS["kd"]] + raw[:, GRAD_CHANNELS["ks"]] - 1.0)
    return (below.square().sum(-1) + above.square().sum(-1) + energy.square().sum(-1)).mean()


def regularisers(out: dict[str, torch.Tensor], settings: dict) -> dict[str, torch.Tensor]:
    """The weighted regularisers of Eq. 11 (beta, theta, zeta) for the network's outputs."""
    terms = {"value": settings["zeta"] * value_loss(out["raw"])}
    if "probabilities" in out:
        terms["category"] = settings["beta"] * category_loss(out["probabilities"])
        terms["texture"] = settings["theta"] * texture_loss(out["detail"])
    return terms
