"""Baking a material into the renderer's atlas maps (scene/types.py Atlas/Maps, scene/atlas.py).

Atlas texels know their surface point (AtlasTexels.position, .normal), so a material is evaluated
at surface coordinates in meters, not at atlas UVs: charts are cut and packed arbitrarily, and a
pattern laid out in atlas UV would jump at every seam. The surface coordinates are either a
plane's (origin, u axis, v axis: a room's wall or floor, continuous across all its triangles) or
box mapping (each texel projected along its normal's dominant axis), divided by
`meters_per_unit` (the length one UV unit of the material's transform spans on the surface).

`texel_coordinates` picks the texels of some faces and their coordinates; `evaluate_texels`
gives kd, ks, ka there as torch tensors (the joint optimisation scatters them into the maps and
backpropagates the adjoint's map gradients to the parameters); `bake_maps` writes them into a
copy of the maps, grown a few texels into the empty gutter around the charts (the renderer's
nearest-texel lookup can land there, scene/atlas.py).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
import torch

from ..scene.atlas import AtlasTexels, dilate
from .base import Material, Transform

__all__ = ["TexelCoordinates", "texel_coordinates", "evaluate_texels", "bake_maps"]

# Box mapping: for a normal along x, y or z, the two other axes as (u, v), v up where it can be.
_BOX_AXES = {0: (2, 1), 1: (0, 2), 2: (0, 1)}


class TexelCoordinates(NamedTuple):
    selected: np.ndarray  # (H, W) bool: the texels the material covers
    covered: np.ndarray  # (H, W) bool: texels of any triangle (the rest is gutter)
    uv: np.ndarray  # (n, 2) float32 surface coordinates of the selected texels, row-major order


def _surface_uv(position: np.ndarray, normal: np.ndarray, plane) -> np.ndarray:
    if plane is not None:
        origin, u_axis, v_axis = (np.asarray(a, np.float64) for a in plane)
        d = position - origin
        return np.stack([d @ u_axis, d @ v_axis], axis=1)
    axis = np.argmax(np.abs(normal), axis=1)
    uv = np.empty((len(position), 2))
    for a, (iu, iv) in _BOX_AXES.items():
        on = axis == a
        uv[on] = position[on][:, [iu, iv]]
    return uv


def texel_coordinates(texels: AtlasTexels, faces=None, plane=None, meters_per_unit: float = 1.0) -> TexelCoordinates:
    """The texels of triangles `faces` (all covered texels if None) and their surface
    coordinates (module docstring); `plane` = (origin, u_axis, v_axis), unit axes in meters."""
    covered = np.asarray(texels.mask, bool)
    selected = covered if faces is None else covered & np.isin(texels.triangle, np.asarray(faces))
    position = np.asarray(texels.position, np.float64)[selected]
    normal = np.asarray(texels.normal, np.float64)[selected]
    uv = _surface_uv(position, normal, plane) / float(meters_per_unit)
    return TexelCoordinates(selected, covered, uv.astype(np.float32))


def evaluate_texels(
    coords: TexelCoordinates,
    material: Material,
    params=None,
    transform: Transform = Transform(),
    footprint: float = 0.0,
):
    """kd (n, 3), ks (n,), ka (n,) at the selected texels, differentiable in `params`."""
    return material.evaluate(torch.from_numpy(coords.uv), params, transform, footprint)


def bake_maps(
    maps,
    coords: TexelCoordinates,
    material: Material,
    params=None,
    transform: Transform = Transform(),
    dilation: int = 2,
    footprint: float = 0.0,
):
    """A copy of `maps` (an Atlas or Maps) with kd, ks (grey) and ka of the material written at the
    selected texels and grown `dilation` texels into the gutter; other texels are unchanged."""
    with torch.no_grad():
        kd, ks, ka = (t.numpy() for t in evaluate_texels(coords, material, params, transform, footprint))
    out = dataclasses.replace(maps, **{f.name: getattr(maps, f.name).copy() for f in dataclasses.fields(maps)})
    writable = coords.selected | ~coords.covered
    for name, values in (("kd", kd), ("ks", np.repeat(ks[:, None], 3, axis=1)), ("ka", ka)):
        target = getattr(out, name)
        grid = np.zeros(target.shape, np.float32)
        grid[coords.selected] = values
        grid, grown = dilate(grid, coords.selected, dilation)
        write = grown & writable
        target[write] = grid[write]
    return out
