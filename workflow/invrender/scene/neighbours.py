"""Which texels are neighbours on the surface, and which sky texels by direction: the pairs the
smoothness priors of the texel-parametrised materials compare (duplicates_material, milo's
`texels` model)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .atlas import AtlasTexels
from .cubemap import texel_directions

SKY_NEIGHBOURS = 8  # each sky texel's neighbours in the sky prior: the 3 x 3 block around it


def point_spacing(points: np.ndarray, tree: cKDTree | None = None) -> float:
    """The median distance from a point to the nearest other point that is not at the same
    place (0 for fewer than two points)."""
    points = np.asarray(points, np.float64)
    if len(points) < 2:
        return 0.0
    nearest = (tree or cKDTree(points)).query(points, k=2)[0][:, 1]
    apart = nearest[nearest > 0]
    return float(np.median(apart)) if len(apart) else 0.0


def point_neighbour_pairs(points: np.ndarray, radius: float) -> np.ndarray:
    """(m, 2) indices of points within `radius` spacings (point_spacing) of each other."""
    points = np.asarray(points, np.float64)
    if len(points) < 2:
        return np.zeros((0, 2), np.int64)
    tree = cKDTree(points)
    spacing = point_spacing(points, tree)
    return tree.query_pairs(radius * max(spacing, 1e-12), output_type="ndarray").astype(np.int64)


def neighbour_pairs(texels: AtlasTexels, radius: float) -> np.ndarray:
    """(m, 2) flat atlas indices of covered texels within `radius` texel spacings in 3D, across
    chart seams too."""
    flat = np.flatnonzero(texels.mask.reshape(-1))
    points = texels.position.reshape(-1, 3)[flat]
    return flat[point_neighbour_pairs(points, radius)]


def sky_neighbour_pairs(n: int, below: np.ndarray | None = None, k: int = SKY_NEIGHBOURS) -> np.ndarray:
    """(m, 2) flat indices of each 6 x n x n cube texel and its k nearest by direction, across
    the cube's edges too, but never across the horizon `below` ((6, n, n) bool, or None): sky
    and ground are not alike, and the sky would bleed into the ground no copy sees. Nearest
    rather than within a radius: a face's centre texels span about three times the solid angle
    of its corners', so a radius leaves them alone."""
    directions = texel_directions(n).reshape(-1, 3).astype(np.float64)
    k = min(k, len(directions) - 1)
    _, nearest = cKDTree(directions).query(directions, k=k + 1)
    pairs = np.stack([np.repeat(np.arange(len(directions)), k), nearest[:, 1:].reshape(-1)], 1)
    if below is not None:
        side = np.asarray(below).reshape(-1)
        pairs = pairs[side[pairs[:, 0]] == side[pairs[:, 1]]]
    return np.unique(np.sort(pairs, 1), axis=0)
