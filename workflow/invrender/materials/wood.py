"""Wood: growth rings seen on a plank, with fine grain along the fibres.

The fibres run along material x; the rings cross y once per unit, bent by Perlin fBm
(`distortion`, in ring widths). Within a ring the wood darkens gradually from the early wood
(`light`) to the late wood (`dark`) over its last `latewood` fraction, then changes within a
small `edge` at the next ring, as a tree grows. `grain` is the amplitude of fibre streaks (fBm stretched 12:1)."""

from __future__ import annotations

import torch

from .base import Material, Param
from .fields import fbm, perlin_noise, smoothstep

# Streaks much longer along the fibres than across them.
_GRAIN_STRETCH = torch.tensor([1.5, 18.0])
_RING_WARP = torch.tensor([0.35, 1.0])


class Wood(Material):
    name = "wood"
    PARAMS = (
        Param("light", (0.55, 0.35, 0.18), 0.0, 0.9),
        Param("dark", (0.3, 0.16, 0.07), 0.0, 0.9),
        Param("latewood", 0.35, 0.05, 0.9),
        Param("distortion", 0.4, 0.0, 1.0),
        Param("grain", 0.25, 0.0, 0.6),
    )

    def albedo(self, p, P, footprint):
        warp = fbm(p * _RING_WARP.to(p.dtype), octaves=3, basis=perlin_noise, salt=5)
        t = p[:, 1] + 2.0 * P["distortion"] * warp
        phase = t - torch.floor(t)
        # The late wood ends within the ring's last `edge` (a sharp but continuous drop: a jump
        # would alias, and its position's derivative would be lost to autograd).
        edge = max(footprint, 0.03)
        ring = (smoothstep(1.0 - P["latewood"], 1.0 - edge, phase) * (1.0 - smoothstep(1.0 - edge, 1.0, phase)))[
            :, None
        ]
        streak = fbm(p * _GRAIN_STRETCH.to(p.dtype), octaves=3, basis=perlin_noise, salt=9)
        return torch.lerp(P["light"], P["dark"], ring) * (1.0 + 2.0 * P["grain"] * streak)[:, None]
