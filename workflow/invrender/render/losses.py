"""Losses shared by the training stages: the image loss on the path tracer's estimates (MILO
Eq. 5 and its squared forms), whose derivative per ray the adjoint takes, and the energy bound
of the material model (kd + ks <= 1 per channel: the Lambert and specular lobes together may not
reflect more than arrives, docs/renderer.md)."""

from __future__ import annotations

import numpy as np

from .scene_buffers import LUMINANCE

__all__ = ["IMAGE_LOSSES", "image_loss", "energy_excess"]

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


def energy_excess(kd, ks):
    """Per texel and channel, the squared excess of kd + ks over 1 (torch tensors)."""
    import torch

    return torch.relu(kd + ks - 1.0).square()


def log_sky_variation(log_sky, pairs, limit: float):
    """Mean |log kg_i - log kg_j| over neighbouring sky texels `pairs` ((m, 2) indices into the
    (texels, 3) `log_sky`, clamped below `limit`), RGB summed: L1 in log radiance, so a horizon or
    a sun stays sharp while directions nothing constrains take their neighbours' values instead
    of whatever fits the noise. Zero without pairs (torch tensors)."""
    import torch

    if not len(pairs):
        return torch.zeros(())
    g = torch.clamp(log_sky, max=limit).reshape(-1, 3)
    return (g[pairs[:, 0]] - g[pairs[:, 1]]).abs().sum(-1).mean()
