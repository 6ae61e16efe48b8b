"""The floor the copies rest on, as a plane that carves the hull (`hull_floor`, hull.carve's floors).

Where a copy stands on a face, no silhouette can carve below that face: the points under it
project onto the copy's own pixels (it hides them) or onto the floor in front of it, which the
other copies' views may not reach. The hull keeps a skirt there (box-10-hd: up to 12 mm below the
face the upright copies stand on, 3.3 mm mean over that face, against 0.7-0.9 mm on the faces the
camera sees). Copies rest on one floor: no part of any copy lies below it, so in each copy's
object frame the half-space under the floor is outside.

The plane, in the camera frame, from the copies alone: each copy's contact point along the
current normal (the mean of its points within CONTACT of its lowest), a total least-squares plane
through the contacts, again until it settles, starting from the camera's up. The points are
COLMAP's triangulated ones where there are MIN_POINTS of them (the lowest TRIM of each copy's left
out: a point triangulated off the surface), else the hull's vertices. The points lie on the object
(the face a copy stands on is seen by the others); the hull's lowest vertices do not: under every
face the hull keeps fins and skirts that no silhouette carves, and a floor through their tips cut
nothing (box-6-hd: 8-24 mm below the copies' lowest points, which are within 2 mm of the true
bottoms). A copy whose contact lies more than OUTLIER below the median is left out of the fit:
its lowest point is a skirt, not the floor. The offset is the lowest of the kept contacts, lowered
by SLACK (a copy resting on a corner, or lifted a little, must not lose its true surface). A copy
whose contact lies more than MISPOSED below the floor is not on a skirt: its pose or the fit is
wrong (on a Mitsuba capture two wrong copies of six tilted the fit 1.5 diagonals over three right
ones), and its floor would carve the whole object, so it gets none (`Floor.misposed`).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from ..scene.resting import MIN_COPIES, contacts, resting_normal
from ..scene.types import Mesh

__all__ = ["Floor", "fit_floor", "floor_plane", "floors_in_object_frame"]

log = logging.getLogger(__name__)

CONTACT = 0.005  # of the mesh's diagonal: vertices this close to a copy's lowest are its contact
OUTLIER = 0.02  # of the diagonal: a contact this far below the median is a skirt's
SLACK = 0.005  # of the diagonal: the floor is lowered by this much before it carves
MIN_POINTS = 50  # COLMAP's points that fix the contacts; fewer, and the hull's vertices do
TRIM = 0.01  # of a copy's points, the lowest share left out of its contact
MISPOSED = 0.3  # of the diagonal: a contact this far below the floor is a wrong pose (skirts: <= 0.16)


class Floor(NamedTuple):
    normal: np.ndarray  # (3,) camera frame, on the side of up
    offset: float  # n . X = offset
    misposed: list[int]  # copies whose contact lies more than MISPOSED below it: no floor for them

    @property
    def plane(self) -> tuple[np.ndarray, float]:
        return self.normal, self.offset


def floor_plane(mesh: Mesh, poses: dict, up, points=None) -> tuple[np.ndarray, float] | None:
    """(normal, offset) of ``fit_floor``'s floor, None where it has none."""
    fitted = fit_floor(mesh, poses, up, points)
    return None if fitted is None else fitted.plane


def fit_floor(mesh: Mesh, poses: dict, up, points=None) -> Floor | None:
    """The floor n . X = offset in the camera frame, n on the side of ``up`` (module docstring;
    the fit: scene/resting.py), from COLMAP's ``points`` (the mesh's frame) when there are enough,
    else from the mesh's vertices, with the copies posed too far under it; None with fewer than
    three copies."""
    if len(poses) < MIN_COPIES:
        return None
    positions = np.asarray(mesh.positions, np.float64)
    diagonal = float(np.linalg.norm(np.ptp(positions, axis=0)))
    on_object = points is not None and len(points) >= MIN_POINTS
    source, trim = (np.asarray(points, np.float64), TRIM) if on_object else (positions, 0.0)
    worlds = [source @ T[:3, :3].T + T[:3, 3] for _, T in sorted(poses.items())]
    normal = resting_normal(worlds, up, CONTACT * diagonal, OUTLIER * diagonal, trim)
    height = contacts(worlds, normal, CONTACT * diagonal, trim) @ normal
    kept = height >= np.median(height) - OUTLIER * diagonal
    log.info(
        "floor (from %s): %d of %d copies' contacts fit it; %d left out, their lowest %.3g of the diagonal below it",
        "COLMAP's points" if on_object else "the hull", int(kept.sum()), len(height), int((~kept).sum()),
        float((height[kept].min() - height.min()) / diagonal),
    )  # fmt: skip
    offset = float(height[kept].min() - SLACK * diagonal)
    misposed = [i for i, h in zip(sorted(poses), height, strict=True) if h < offset - MISPOSED * diagonal]
    return Floor(normal, offset, misposed)


def floors_in_object_frame(plane: tuple[np.ndarray, float], poses: dict) -> list[tuple[np.ndarray, float]]:
    """The camera-frame floor n . X = d as each copy's object-frame plane (R^T n, d - n . t)."""
    normal, offset = plane
    return [(T[:3, :3].T @ normal, offset - float(normal @ T[:3, 3])) for _, T in sorted(poses.items())]
