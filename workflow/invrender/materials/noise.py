"""Noise: two colours mixed by fBm, for stone, plaster, concrete and carpet.

The basis blends Perlin gradient noise (smooth blobs) with value noise (blockier, brighter
spots) by `value_mix`; `persistence` is the fBm's amplitude ratio between octaves (rougher
texture as it grows); `contrast` stretches the mix around its middle."""

from __future__ import annotations

import torch

from .base import Material, Param
from .fields import fbm, perlin_noise, value_noise

_OCTAVES = 5
_BASE_FREQUENCY = 2.0  # about one blob per material unit


class Noise(Material):
    name = "noise"
    PARAMS = (
        Param("colour_a", (0.55, 0.55, 0.52), 0.0, 0.9),
        Param("colour_b", (0.3, 0.3, 0.3), 0.0, 0.9),
        Param("persistence", 0.5, 0.25, 0.8),
        Param("value_mix", 0.0, 0.0, 1.0),
        Param("contrast", 1.0, 0.2, 2.0),
    )

    def albedo(self, p, P, footprint):
        q = p * _BASE_FREQUENCY
        perlin = fbm(q, _OCTAVES, P["persistence"], basis=perlin_noise, salt=17)
        value = fbm(q, _OCTAVES, P["persistence"], basis=value_noise, salt=19) - 0.5
        n = torch.lerp(perlin, value, P["value_mix"])
        # Perlin fBm's spread is about 0.2: a contrast of 1 spans most of [0, 1].
        t = torch.clamp(0.5 + 2.5 * P["contrast"] * n, 0.0, 1.0)[:, None]
        return torch.lerp(P["colour_b"], P["colour_a"], t)
