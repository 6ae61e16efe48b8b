"""Tiles: rows of rectangular tiles in grout, each tile's brightness varied at random.

Rows are one material unit high, tiles `aspect` units wide, every row shifted by `bond` tile
widths (0: a grid, 0.5: running bond brickwork). `grout_width` is the joint's width in
material units; `variation` the largest relative change of a tile's brightness."""

from __future__ import annotations

import torch

from .base import Material, Param
from .fields import cell_random, soft_step


class Tiles(Material):
    name = "tiles"
    PARAMS = (
        Param("tile_colour", (0.6, 0.55, 0.5), 0.0, 0.9),
        Param("grout_colour", (0.2, 0.2, 0.2), 0.0, 0.9),
        Param("grout_width", 0.08, 0.02, 0.25),
        Param("variation", 0.15, 0.0, 0.5),
        Param("aspect", 1.0, 1.0, 3.0),
        Param("bond", 0.0, 0.0, 0.5),
    )

    def albedo(self, p, P, footprint):
        y = p[:, 1]
        row = torch.floor(y)
        xs = p[:, 0] / P["aspect"] + P["bond"] * row
        col = torch.floor(xs)
        fx = (xs - col) * P["aspect"]  # material units from the tile's left edge
        fy = y - row
        # Distance to the nearest joint; the grout is the band of half its width on each side.
        d = torch.minimum(torch.minimum(fx, P["aspect"] - fx), torch.minimum(fy, 1.0 - fy))
        tile = soft_step(d, 0.5 * P["grout_width"], max(footprint, 0.01))[:, None]
        shade = 1.0 + P["variation"] * (2.0 * cell_random(col.long(), row.long(), salt=3).to(p.dtype) - 1.0)
        return torch.lerp(P["grout_colour"], P["tile_colour"] * shade[:, None], tile)
