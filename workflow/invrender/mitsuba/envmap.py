"""The kg cube map (scene/cubemap.py defines its lookup) as a Mitsuba lat-long `envmap`.

Mitsuba's `envmap` (measured on mitsuba 3.9.1, tests/mitsuba/test_mitsuba_bridge.py): pixel
(row i, column j) of an H x W image holds the radiance arriving from (seen looking along) world
direction d = (sin phi sin theta, cos theta, -cos phi sin theta), theta = pi i / (H - 1),
phi = 2 pi (j + 1/2) / W: +Y is up, phi = 0 looks along -Z, phi = pi/2 along +X; values in
between are bilinear. So a directly seen cube-texel edge is blurred over one lat-long pixel, and
at the default size the irradiance error is below 0.1 % even for a white-noise kg.
"""

from __future__ import annotations

import numpy as np

from invrender.scene.cubemap import lookup_cube

# Lat-long width per cube face texel: Mitsuba interpolates the lat-long image bilinearly, and with
# 32 lat-long pixels per cube texel row (at least 1024) the irradiance from a white-noise kg
# (the worst case) moves by < 0.1 % (measured: N = 8..64 -> 0.04-0.07 %).
ENVMAP_WIDTH_PER_TEXEL = 32
MIN_ENVMAP_WIDTH = 1024


def envmap_directions(width: int, height: int) -> np.ndarray:
    """World direction of each pixel of a Mitsuba `envmap` of that size: (height, width, 3)."""
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], -1)


def default_envmap_size(kg: np.ndarray) -> tuple[int, int]:
    """(width, height) of the lat-long image that represents kg to < 0.1 % in irradiance."""
    width = max(MIN_ENVMAP_WIDTH, ENVMAP_WIDTH_PER_TEXEL * kg.shape[1])
    return width, width // 2


def cube_to_latlong(kg: np.ndarray, size=None) -> np.ndarray:
    """Resample the (6, N, N, 3) kg cube map to a Mitsuba lat-long image (H, W, 3), float32:
    each pixel gets the nearest cube texel at its direction. size = (width, height), by
    default `default_envmap_size(kg)`."""
    width, height = size or default_envmap_size(kg)
    return lookup_cube(kg, envmap_directions(width, height)).astype(np.float32)
