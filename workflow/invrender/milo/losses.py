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
from .network import LOWER, UPPER


def image_loss(radiance: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """Eq. 5 over the batch, as a mean of || L_j - T_j ||_2, and dLoss/dL_j (n, 3)."""
    residual = radiance.astype(np.float64) - target
    norm = np.linalg.norm(residual, axis=1, keepdims=True)
    adjoint = np.where(norm > 0, residual / np.where(norm > 0, norm, 1.0), 0.0) / len(residual)
    return float(norm.mean()), adjoint


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
