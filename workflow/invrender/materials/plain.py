"""Plain: one colour everywhere, the paper's homogeneous material (section 4.4: "constant
albedo, roughness, specular"), and the fallback when no texture explains a crop better."""

from __future__ import annotations

from .base import Material, Param


class Plain(Material):
    name = "plain"
    PARAMS = (Param("colour", (0.5, 0.5, 0.5), 0.0, 0.9),)

    def albedo(self, p, P, footprint):
        return P["colour"].expand(len(p), 3)
