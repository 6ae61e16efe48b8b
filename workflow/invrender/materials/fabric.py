"""Fabric: a plain weave, warp threads (along y) and weft threads (along x) passing over and
under each other in turn, two threads per material unit each way.

`thread_width` is the fraction of its pitch a thread covers (the rest is the dark gap between
threads, where little light comes back); `shading` darkens each thread towards its sides, as a
cylinder lit from the front; `fuzz` is the amplitude of fibre noise."""

from __future__ import annotations

import torch

from .base import Material, Param
from .fields import fbm, soft_step, value_noise

_THREADS_PER_UNIT = 2.0
_GAP_DARKNESS = 0.15  # the gap shows the layer below, in shadow


class Fabric(Material):
    name = "fabric"
    PARAMS = (
        Param("warp", (0.15, 0.2, 0.4), 0.0, 0.9),
        Param("weft", (0.6, 0.6, 0.65), 0.0, 0.9),
        Param("thread_width", 0.8, 0.4, 1.0),
        Param("shading", 0.5, 0.0, 1.0),
        Param("fuzz", 0.1, 0.0, 0.5),
    )

    def _thread(self, across, P, edge):
        """Coverage and shading of a thread centred at across = 0.5 of its pitch."""
        half = 0.5 * P["thread_width"]
        r = torch.abs(across - 0.5)
        cover = 1.0 - soft_step(r, half, edge)
        shade = 1.0 - P["shading"] * torch.clamp(r / half, max=1.0) ** 2
        return cover, shade

    def albedo(self, p, P, footprint):
        q = p * _THREADS_PER_UNIT
        cell = torch.floor(q)
        f = q - cell
        edge = max(footprint * _THREADS_PER_UNIT, 0.02)
        warp_cover, warp_shade = self._thread(f[:, 0], P, edge)
        weft_cover, weft_shade = self._thread(f[:, 1], P, edge)
        warp_on_top = (torch.remainder(cell[:, 0] + cell[:, 1], 2.0) < 0.5).to(p.dtype)
        warp = warp_cover * torch.lerp(torch.ones_like(weft_cover), 1.0 - weft_cover, warp_on_top)
        weft = weft_cover * (1.0 - warp)
        gap = 1.0 - warp - weft
        mean = 0.5 * (P["warp"] + P["weft"])
        colour = (
            (warp * warp_shade)[:, None] * P["warp"]
            + (weft * weft_shade)[:, None] * P["weft"]
            + (gap[:, None] * _GAP_DARKNESS) * mean
        )
        fibres = fbm(q * 4.0, octaves=2, basis=value_noise, salt=13) - 0.5
        return colour * (1.0 + 2.0 * P["fuzz"] * fibres)[:, None]
