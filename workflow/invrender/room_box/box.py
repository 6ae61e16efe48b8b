"""The room box: an upright box (+Y up, the floor its bottom face) seen from inside.

A box is ``center`` (3,), ``size`` (3,) and ``yaw_deg`` (rotation about +Y), as the room
generator's truth/room.json writes it: world = R_y(yaw) @ (size * v) + center for v in the
unit cube [-0.5, 0.5]^3. R_y is the right-handed rotation about +Y, the axis-angle (0, yaw, 0)
of render/silhouette.py's pose vector, so ``box_params`` hands a box to that renderer as is.

``cast_box`` is the exact, non-differentiable reference: which face (wall, floor, ceiling) and
which camera-space depth each pixel centre sees. The stage's metrics and the tests' synthetic
inputs use it; the refinement uses the differentiable renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.cameras import pixel_directions
from ..scene.room_photo import yaw_matrix
from ..scene.types import Camera

__all__ = [
    "BOX_CLASSES",
    "RoomBox",
    "OrientedBox",
    "rotation_y",
    "box_corners",
    "box_mesh",
    "cast_box",
    "matched_distances",
]

# The room stage's classes, in the order of its masks. The same names as scene/room_photo.py's
# ROOM_CLASSES (wall, floor, ceiling come first there too).
BOX_CLASSES = ("wall", "floor", "ceiling")
WALL, FLOOR, CEILING = range(3)


@dataclass
class RoomBox:
    center: np.ndarray  # (3,) world, the box's centre (its floor at center[1] - size[1] / 2)
    size: np.ndarray  # (3,) extents along the box's own x, y (height), z
    yaw_deg: float  # rotation about +Y

    def __post_init__(self):
        self.center = np.asarray(self.center, np.float64).reshape(3)
        self.size = np.asarray(self.size, np.float64).reshape(3)
        self.yaw_deg = float(self.yaw_deg)

    def to_json(self) -> dict:
        return {
            "center": [round(float(v), 6) for v in self.center],
            "size": [round(float(v), 6) for v in self.size],
            "yaw_deg": round(self.yaw_deg, 4),
        }

    @classmethod
    def from_json(cls, doc: dict) -> RoomBox:
        return cls(doc["center"], doc["size"], doc.get("yaw_deg", 0.0))


@dataclass
class OrientedBox:
    """A box at any rotation (the refinement's result before the world is turned to make it
    upright): world = rotation @ (size * v) + center."""

    rotation: np.ndarray  # (3, 3)
    center: np.ndarray  # (3,)
    size: np.ndarray  # (3,)

    def upright(self, camera: Camera) -> tuple[RoomBox, Camera]:
        """The same box and camera in the world where the box has yaw 0 and no tilt, its floor at
        y = 0 and its centre above the origin: p' = rotation^T (p - o), o its floor's centre."""
        origin = self.center - self.rotation @ np.array([0.0, self.size[1] / 2, 0.0])
        R = np.asarray(camera.R) @ self.rotation
        t = np.asarray(camera.R) @ origin + np.asarray(camera.t)
        moved = Camera(camera.name, camera.model, camera.width, camera.height, camera.params, R, t)
        return RoomBox([0.0, self.size[1] / 2, 0.0], self.size, 0.0), moved


def rotation_y(yaw_rad: float) -> np.ndarray:
    return yaw_matrix(np.degrees(yaw_rad))


UNIT_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])


def box_corners(box: RoomBox) -> np.ndarray:
    """(8, 3) world corners."""
    return (UNIT_CORNERS * box.size) @ rotation_y(np.radians(box.yaw_deg)).T + box.center


def box_mesh() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The unit cube's (8, 3) vertices, (12, 3) faces wound counter-clockwise seen from inside
    (the room's side) and (12,) face labels (indices into BOX_CLASSES)."""
    index = {tuple(c): i for i, c in enumerate(UNIT_CORNERS)}
    faces, labels = [], []
    for axis in range(3):
        for sign in (-0.5, 0.5):
            u, v = [a for a in range(3) if a != axis]
            quad = []
            for a, b in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
                corner = [0.0, 0.0, 0.0]
                corner[axis], corner[u], corner[v] = sign, a, b
                quad.append(index[tuple(corner)])
            # (u, v, axis) is right-handed: this quad is counter-clockwise seen from +axis, so it
            # faces inwards on the -axis side and must be reversed on the +axis side.
            if sign > 0:
                quad = quad[::-1]
            faces += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
            label = WALL if axis != 1 else (FLOOR if sign < 0 else CEILING)
            labels += [label, label]
    return UNIT_CORNERS.copy(), np.array(faces, np.int64), np.array(labels, np.int64)


def cast_box(box: RoomBox, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The face label (H, W) int (-1 where the ray misses) and camera-space depth (H, W) (0 where
    it misses) at each pixel centre: the exact box, by the slab test in its own frame (an affine
    map keeps the ray parameter, and with pixel_directions' z = 1 the parameter is the depth)."""
    directions = pixel_directions(camera).reshape(-1, 3)
    inverse = rotation_y(np.radians(box.yaw_deg)).T
    origin = (inverse @ (camera.center - box.center)) / box.size
    direction = directions @ inverse.T / box.size
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = (-0.5 - origin) / direction
        hi = (0.5 - origin) / direction
    near, far = np.fmin(lo, hi), np.fmax(lo, hi)
    enter, leave = near.max(axis=1), far.min(axis=1)
    # From inside (the usual case) the ray leaves through a face; from outside it enters one.
    inside = enter <= 0
    t = np.where(inside, leave, enter)
    axis = np.where(inside, far.argmin(axis=1), near.argmax(axis=1))
    hit = (leave >= enter) & (t > 0)
    point = origin + t[:, None] * direction
    side = np.take_along_axis(point, axis[:, None], axis=1)[:, 0] > 0
    label = np.where(axis == 1, np.where(side, CEILING, FLOOR), WALL)
    label = np.where(hit, label, -1)
    depth = np.where(hit, t, 0.0)
    shape = (camera.height, camera.width)
    return label.reshape(shape), depth.reshape(shape)


def matched_distances(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(8,) distance from each truth corner to the estimated corner matched to it one to one, by
    least total distance (the box's symmetries make "which corner is which" a matter of the
    matching, not of the parameters)."""
    from scipy.optimize import linear_sum_assignment

    distance = np.linalg.norm(estimate[:, None, :] - truth[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(distance)
    return distance[rows, cols][np.argsort(cols)]
