"""Geometry: UV atlases over meshes (xatlas) and the texel -> surface point tables built on them."""

from .atlas import AtlasTexels, UVAtlas, bake, dilate, rasterize_atlas, texel_index, unwrap

__all__ = ["AtlasTexels", "UVAtlas", "bake", "dilate", "rasterize_atlas", "texel_index", "unwrap"]
