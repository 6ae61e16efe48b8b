"""Our parameter maps as Mitsuba `bitmap` textures: nearest texel, raw (linear) values, clamped
at the border, as the kernels read the atlas.

Mitsuba's `bitmap` reads row floor(v H), row 0 first: v points down. Our atlas has v up
(row = floor((1 - v) H)), so meshes carry texcoords (u, 1 - v) (mesh.py).
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np


def bitmap_texture(image: np.ndarray) -> dict:
    """A Mitsuba `bitmap` texture dict from an (H, W), (H, W, 1) or (H, W, 3) array, looked up
    at Mitsuba texcoords (u, 1 - v)."""
    image = np.array(image, dtype=np.float32, order="C")  # a writeable, contiguous copy
    if image.ndim == 2:
        image = image[..., None]
    return {"type": "bitmap", "bitmap": mi.Bitmap(image), "raw": True, "filter_type": "nearest", "wrap_mode": "clamp"}


def constant_map(value, channels: int) -> np.ndarray:
    """A 1 x 1 map of `value` (a number or `channels` numbers), or `value` itself if it is a map."""
    if np.ndim(value) >= 2:
        return np.asarray(value, np.float32)
    return np.broadcast_to(np.asarray(value, np.float32), (1, 1, channels))


def texture_property(props, name: str, default, channels: int):
    """A plugin's texture property: a texture object as given, or a number / `channels` numbers
    (or nothing: `default`) as a 1 x 1 bitmap."""
    if name not in props:
        return mi.load_dict(bitmap_texture(constant_map(default, channels)))
    value = props[name]
    if isinstance(value, (int, float)) or (isinstance(value, (list, tuple)) and len(value) == channels):
        return mi.load_dict(bitmap_texture(constant_map(value, channels)))
    return value
