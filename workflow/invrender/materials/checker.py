"""Checker: two colours in squares, one pair of squares per material unit along each axis."""

from __future__ import annotations

import torch

from .base import Material, Param
from .fields import soft_step


def square_wave(x: torch.Tensor, footprint: float) -> torch.Tensor:
    """0 on [0, 0.5), 1 on [0.5, 1) of each unit, its edges blurred over `footprint` (plus a
    floor, so that the edges stay differentiable under a shift)."""
    shifted = x + 0.25
    tri = 2.0 * torch.abs(shifted - torch.floor(shifted) - 0.5)  # 0 at x = 1/4, 1 at x = 3/4
    return 1.0 - soft_step(tri, 0.5, max(2.0 * footprint, 0.02))


class Checker(Material):
    name = "checker"
    PARAMS = (
        Param("colour_a", (0.8, 0.8, 0.8), 0.0, 0.9),
        Param("colour_b", (0.1, 0.1, 0.1), 0.0, 0.9),
    )

    def albedo(self, p, P, footprint):
        a, b = square_wave(p[:, 0], footprint), square_wave(p[:, 1], footprint)
        mix = (a + b - 2 * a * b)[:, None]  # soft exclusive or
        return torch.lerp(P["colour_a"], P["colour_b"], mix)
