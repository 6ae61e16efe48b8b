"""The `geometry` stage: a capture's mesh or point cloud cleaned, simplified and unwrapped
(``stage.run``); the atlas itself (UVs, texel -> surface point) is a scene format: scene/atlas.py."""

from .stage import run

__all__ = ["run"]
