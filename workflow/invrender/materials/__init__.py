"""Differentiable procedural materials (PSDR-Room section 4.4): six material types in torch,
baked into the renderer's maps, a Gram-matrix texture loss from a fixed random-weight network,
retrieval of a material for a photo crop, the transform search and the parameter fit.
docs/materials.md is the guide."""

from .base import Material, Param, Transform
from .library import MATERIALS, PRESETS, Preset, material, preset

__all__ = ["Material", "Param", "Transform", "MATERIALS", "PRESETS", "Preset", "material", "preset"]
