"""The plane copies of an object rest on, from their posed vertices alone (shared by the duplicates
stage, whose hull it carves, and the material stage, whose support it places).

Each copy touches the plane at its lowest points along the plane's normal; starting from the
camera's up (a photograph of objects on a table is taken above it, upright), the normal is refitted
to one contact point per copy (the mean of its vertices within ``tolerance`` of its lowest) by
total least squares until it settles. With ``outlier``, contacts more than that below the median
are left out of each fit: a copy whose lowest point is not where it touches the plane (a visual
hull's skirt under the face it stands on) must not tilt it. With fewer than three copies the
contacts do not fix a plane and ``up`` is kept.
"""

from __future__ import annotations

import numpy as np

__all__ = ["contacts", "resting_normal"]

REFITS = 20
MIN_COPIES = 3


def contacts(worlds: list[np.ndarray], normal: np.ndarray, tolerance: float, trim: float = 0.0) -> np.ndarray:
    """One point per copy (world vertices or points, one array each): the mean of its points within
    ``tolerance`` of its lowest along ``normal``, the lowest ``trim`` share of them left out first
    (a few points triangulated off the surface must not set the contact)."""
    points = []
    for world in worlds:
        height = world @ normal
        lowest = np.quantile(height, trim, method="higher") if trim > 0 else height.min()
        near = (height >= lowest) & (height <= lowest + tolerance)
        points.append(world[near].mean(0))
    return np.array(points)


def resting_normal(
    worlds: list[np.ndarray], up, tolerance: float, outlier: float | None = None, trim: float = 0.0
) -> np.ndarray:
    """The unit normal of the plane the copies rest on, on the side of ``up`` (module docstring)."""
    normal = np.asarray(up, np.float64) / np.linalg.norm(up)
    if len(worlds) < MIN_COPIES:
        return normal
    for _ in range(REFITS):
        points = contacts(worlds, normal, tolerance, trim)
        if outlier is not None:
            height = points @ normal
            points = points[height >= np.median(height) - outlier]
        centred = points - points.mean(0)
        if len(points) < MIN_COPIES or np.linalg.norm(centred, axis=1).max() < 1e-9:
            break
        fitted = np.linalg.svd(centred)[2][2]
        fitted = fitted if fitted @ normal > 0 else -fitted
        settled = fitted @ normal > 1 - 1e-12
        normal = fitted
        if settled:
            break
    return normal
