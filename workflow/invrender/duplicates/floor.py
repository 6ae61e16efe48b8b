"""The floor the copies rest on, as a plane that carves the hull (`hull_floor`, hull.carve's floors).

Where a copy stands on a face, no silhouette can carve below that face: the points under it
project onto the copy's own pixels (it hides them) or onto the floor in front of it, which the
other copies' views may not reach. The hull keeps a skirt there (box-10-hd: up to 12 mm below the
face the upright copies stand on, 3.3 mm mean over that face, against 0.7-0.9 mm on the faces the
camera sees). Copies rest on one floor: no part of any copy lies below it, so in each copy's
object frame the half-space under the floor is outside.

The plane, in the camera frame, from the copies alone: each copy's contact point along the
current normal (the mean of its hull vertices within CONTACT of its lowest), a total least-squares
plane through the contacts, again until it settles, starting from the camera's up. A copy whose
contact lies more than OUTLIER below the median is left out of the fit: its lowest point is a
skirt, not the floor. The offset is the lowest of the kept contacts, lowered by SLACK (a copy
resting on a corner, or lifted a little, must not lose its true surface).
"""

from __future__ import annotations

import logging

import numpy as np

from ..scene.resting import MIN_COPIES, contacts, resting_normal
from ..scene.types import Mesh

__all__ = ["floor_plane", "floors_in_object_frame"]

log = logging.getLogger(__name__)

CONTACT = 0.005  # of the mesh's diagonal: vertices this close to a copy's lowest are its contact
OUTLIER = 0.02  # of the diagonal: a contact this far below the median is a skirt's
SLACK = 0.005  # of the diagonal: the floor is lowered by this much before it carves


def floor_plane(mesh: Mesh, poses: dict, up) -> tuple[np.ndarray, float] | None:
    """(normal, offset) of the floor n . X = offset in the camera frame, n on the side of ``up``
    (module docstring; the fit: scene/resting.py); None with fewer than three copies."""
    if len(poses) < MIN_COPIES:
        return None
    positions = np.asarray(mesh.positions, np.float64)
    diagonal = float(np.linalg.norm(np.ptp(positions, axis=0)))
    worlds = [positions @ T[:3, :3].T + T[:3, 3] for _, T in sorted(poses.items())]
    normal = resting_normal(worlds, up, CONTACT * diagonal, OUTLIER * diagonal)
    height = contacts(worlds, normal, CONTACT * diagonal) @ normal
    kept = height >= np.median(height) - OUTLIER * diagonal
    log.info(
        "floor: %d of %d copies' contacts fit it; %d left out, their lowest %.3g of the diagonal below it",
        int(kept.sum()), len(height), int((~kept).sum()), float((height[kept].min() - height.min()) / diagonal),
    )  # fmt: skip
    return normal, float(height[kept].min() - SLACK * diagonal)


def floors_in_object_frame(plane: tuple[np.ndarray, float], poses: dict) -> list[tuple[np.ndarray, float]]:
    """The camera-frame floor n . X = d as each copy's object-frame plane (R^T n, d - n . t)."""
    normal, offset = plane
    return [(T[:3, :3].T @ normal, offset - float(normal @ T[:3, 3])) for _, T in sorted(poses.items())]
