"""The losses of Eq. 11, each a mean so that the weights do not depend on the batch size or the
atlas resolution (the paper's sums tie them to both, section 3.5).

The image loss (Eq. 5) is render/losses.py's (the duplicates material stage uses it too): it is
evaluated on the renderer's estimates and its derivative with respect to each ray's radiance is
handed to the adjoint; the regularisers are torch expressions of the
network's outputs on a random share of the texels.
"""

from __future__ import annotations

import torch

from ..render.adjoint import GRAD_CHANNELS
from ..render.losses import IMAGE_LOSSES, energy_excess, image_loss  # noqa: F401 (milo's losses, in one place)
from .network import LOWER, UPPER


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
    energy = energy_excess(raw[:, GRAD_CHANNELS["kd"]], raw[:, GRAD_CHANNELS["ks"]])
    return (below.square().sum(-1) + above.square().sum(-1) + energy.sum(-1)).mean()


def regularisers(out: dict[str, torch.Tensor], settings: dict) -> dict[str, torch.Tensor]:
    """The weighted regularisers of Eq. 11 (beta, theta, zeta) for the network's outputs."""
    terms = {"value": settings["zeta"] * value_loss(out["raw"])}
    if "probabilities" in out:
        terms["category"] = settings["beta"] * category_loss(out["probabilities"])
        terms["texture"] = settings["theta"] * texture_loss(out["detail"])
    return terms
