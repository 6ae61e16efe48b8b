"""The light stage's initial lights (PSDR-Room section 4.4, "Light initialization").

The paper: split the ceiling into a grid of area lights scaled down by 0.8; remove the lights
that intersect the camera frustum or are completely behind the camera; add one large area light
behind the camera and one per invisible wall ("simulating an invisible window"); turn visible
windows and lamps into emissive objects.

Every light is a ``Quad``: a centre, two edge vectors (the full edges, so the corners are
centre +- e1 / 2 +- e2 / 2) and the unit normal facing into the room (the side it emits to).
Pure geometry in the room box's world (a box as room.json writes it: ``center``, ``size``,
``yaw_deg``, world = R_y(yaw) (size * v) + center for v in the unit cube, as room_box/box.py's
``RoomBox``, which a stage may not import, so any object with those fields does; and the camera
posed in it), so the sizes that are settings are fractions of the box, not meters: room.json's box is in
the depth's units (median depth 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..scene.cameras import pixel_directions
from ..scene.room_photo import yaw_matrix
from ..scene.types import Camera

__all__ = [
    "Quad",
    "LightSettings",
    "ceiling_grid",
    "in_frustum",
    "behind_camera",
    "camera_light",
    "wall_quads",
    "invisible_wall_lights",
    "window_lights",
    "initial_lights",
    "LightSet",
]

SHRINK = 0.8  # the paper's scale of each ceiling cell


@dataclass
class Quad:
    center: np.ndarray  # (3,)
    e1: np.ndarray  # (3,) full edge
    e2: np.ndarray  # (3,) full edge
    normal: np.ndarray  # (3,) unit, into the room
    kind: str  # "ceiling" | "camera" | "wall" | "window" | "lamp"
    name: str = ""

    def corners(self) -> np.ndarray:
        """(4, 3) corners in order around the quad."""
        c, a, b = self.center, self.e1 / 2, self.e2 / 2
        return np.stack([c - a - b, c + a - b, c + a + b, c - a + b])

    @property
    def area(self) -> float:
        return float(np.linalg.norm(np.cross(self.e1, self.e2)))

    def to_json(self) -> dict:
        r = lambda v: [round(float(x), 6) for x in v]  # noqa: E731
        return {
            "kind": self.kind,
            "name": self.name,
            "center": r(self.center),
            "e1": r(self.e1),
            "e2": r(self.e2),
            "normal": r(self.normal),
        }


@dataclass
class LightSettings:
    cell: float = 0.25  # ceiling grid cell, a fraction of the box's larger horizontal extent
    shrink: float = SHRINK
    camera_size: float = 0.5  # the light behind the camera: a fraction of the box's width and height
    camera_offset: float = 0.05  # its distance behind the camera, a fraction of the box's depth
    window_size: float = 0.5  # an invisible wall's light: a fraction of the wall's width and height
    inset: float = 1e-3  # wall lights sit this fraction of the box inside the wall (not coplanar)


def _frame(box) -> np.ndarray:
    """The box's rotation R_y(yaw): its local axes as columns."""
    return yaw_matrix(box.yaw_deg)


def _size(box) -> np.ndarray:
    return np.asarray(box.size, np.float64).reshape(3)


def _center(box) -> np.ndarray:
    return np.asarray(box.center, np.float64).reshape(3)


def ceiling_grid(box, cell: float = 0.25, shrink: float = SHRINK) -> list[Quad]:
    """The ceiling split into cells of about ``cell`` times the larger horizontal extent (at
    least one per axis), each scaled by ``shrink`` about its centre, emitting downwards."""
    R = _frame(box)
    sx, sy, sz = _size(box)
    side = cell * max(sx, sz)
    nx, nz = max(1, round(sx / side)), max(1, round(sz / side))
    quads = []
    for i in range(nx):
        for k in range(nz):
            local = np.array([(i + 0.5) / nx - 0.5, 0.5, (k + 0.5) / nz - 0.5]) * _size(box)
            quads.append(
                Quad(
                    R @ local + _center(box),
                    R[:, 0] * sx / nx * shrink,
                    R[:, 2] * sz / nz * shrink,
                    -R[:, 1],
                    "ceiling",
                    f"ceiling_{i}_{k}",
                )
            )
    return quads


def _clip(points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the part of the polygon (N, 3) where plane[:3] . p + plane[3] >= 0."""
    out = []
    n = len(points)
    for j in range(n):
        p, q = points[j], points[(j + 1) % n]
        dp, dq = plane[:3] @ p + plane[3], plane[:3] @ q + plane[3]
        if dp >= 0:
            out.append(p)
        if (dp >= 0) != (dq >= 0):
            out.append(p + dp / (dp - dq) * (q - p))
    return np.array(out).reshape(-1, 3)


def _frustum_planes(camera: Camera, near: float) -> list[np.ndarray]:
    """The view frustum in camera space as half-spaces a . p + d >= 0: z >= near and the four
    sides through the image's borders (pixel edges 0 and W, 0 and H)."""
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    W, H = camera.width, camera.height
    return [
        np.array([0.0, 0.0, 1.0, -near]),
        np.array([fx, 0.0, cx, 0.0]),  # x / z >= -cx / fx
        np.array([-fx, 0.0, W - cx, 0.0]),  # x / z <= (W - cx) / fx
        np.array([0.0, fy, cy, 0.0]),
        np.array([0.0, -fy, H - cy, 0.0]),
    ]


def _to_camera(camera: Camera, points: np.ndarray) -> np.ndarray:
    return points @ np.asarray(camera.R).T + np.asarray(camera.t)


def in_frustum(quad: Quad, camera: Camera, near: float = 1e-6) -> bool:
    """Whether any part of the quad lies inside the camera's view frustum (would be seen by some
    pixel if nothing occluded it)."""
    polygon = _to_camera(camera, quad.corners())
    for plane in _frustum_planes(camera, near):
        polygon = _clip(polygon, plane)
        if len(polygon) == 0:
            return False
    return True


def behind_camera(quad: Quad, camera: Camera) -> bool:
    """Whether the whole quad is behind the camera's image plane (camera-space z <= 0)."""
    return bool(np.all(_to_camera(camera, quad.corners())[:, 2] <= 0))


def wall_quads(box) -> list[Quad]:
    """The four walls as quads (full size, on the box's faces), normals into the room, named as
    the generator names wall segments: ``wall_+x`` is the wall at the box's local +x side."""
    R = _frame(box)
    sx, sy, sz = _size(box)
    walls = []
    for axis, across, extent in ((0, 2, sx), (2, 0, sz)):
        for sign in (-1.0, 1.0):
            local = np.zeros(3)
            local[axis] = sign * extent / 2
            walls.append(
                Quad(
                    R @ local + _center(box),
                    R[:, across] * _size(box)[across],
                    R[:, 1] * sy,
                    -sign * R[:, axis],
                    "wall",
                    f"wall_{'+' if sign > 0 else '-'}{'xyz'[axis]}",
                )
            )
    return walls


def invisible_wall_lights(box, camera: Camera, size: float = 0.5, inset: float = 1e-3) -> list[Quad]:
    """One light per wall outside the camera's frustum: a window-like quad at the wall's centre,
    ``size`` of its width and height, moved ``inset`` times the box's height into the room."""
    lights = []
    for wall in wall_quads(box):
        if not in_frustum(wall, camera):
            lights.append(
                Quad(
                    wall.center + wall.normal * inset * _size(box)[1],
                    wall.e1 * size,
                    wall.e2 * size,
                    wall.normal,
                    "wall",
                    wall.name,
                )
            )
    return lights


def camera_light(box, camera: Camera, size: float = 0.5, offset: float = 0.05) -> Quad:
    """The large light behind the camera: a vertical quad ``offset`` times the box's largest
    extent behind the camera's centre (kept inside the box), facing the camera's horizontal
    forward direction, ``size`` of the box's width and height."""
    forward = np.asarray(camera.R)[2].copy()
    forward[1] = 0.0
    if np.linalg.norm(forward) < 1e-9:  # looking straight up or down: face the camera's up instead
        forward = -np.asarray(camera.R)[1].copy()
        forward[1] = 0.0
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    R = _frame(box)
    center = camera.center - forward * offset * _size(box).max()
    local = np.clip(R.T @ (center - _center(box)), -_size(box) / 2 * 0.99, _size(box) / 2 * 0.99)
    center = R @ local + _center(box)
    # The box's extent across the forward direction, for the light's width.
    width = np.abs(R.T @ right) @ _size(box)
    return Quad(
        center, right * width * size, np.array([0.0, 1.0, 0.0]) * _size(box)[1] * size, forward, "camera", "camera"
    )


def _wall_hits(wall: Quad, origin: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (u, v) coordinates, along the wall's unit edges from its centre, of the hit points of
    the rays that hit the wall's front within its bounds."""
    u, v = wall.e1 / np.linalg.norm(wall.e1), wall.e2 / np.linalg.norm(wall.e2)
    facing = directions @ wall.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((wall.center - origin) @ wall.normal) / facing
    points = origin + t[:, None] * directions
    pu, pv = (points - wall.center) @ u, (points - wall.center) @ v
    half_u, half_v = np.linalg.norm(wall.e1) / 2, np.linalg.norm(wall.e2) / 2
    inside = (facing < 0) & (t > 0) & (np.abs(pu) <= half_u) & (np.abs(pv) <= half_v)
    return pu[inside], pv[inside]


def ceiling_quad(box) -> Quad:
    """The whole ceiling as a quad, its normal down into the room."""
    R = _frame(box)
    sx, sy, sz = _size(box)
    return Quad(
        R @ np.array([0.0, sy / 2, 0.0]) + _center(box), R[:, 0] * sx, R[:, 2] * sz, -R[:, 1], "ceiling", "ceiling"
    )


def _footprint(quad: Quad, pu: np.ndarray, pv: np.ndarray, kind: str, name: str, inset: float = 0.0) -> Quad:
    """The bounding rectangle of hit points (pu, pv) on ``quad``, moved ``inset`` into the room."""
    u, v = quad.e1 / np.linalg.norm(quad.e1), quad.e2 / np.linalg.norm(quad.e2)
    lo, hi = np.array([pu.min(), pv.min()]), np.array([pu.max(), pv.max()])
    mid = (lo + hi) / 2
    center = quad.center + u * mid[0] + v * mid[1] + quad.normal * inset
    return Quad(center, u * (hi[0] - lo[0]), v * (hi[1] - lo[1]), quad.normal, kind, name)


def window_lights(
    box, camera: Camera, segments: np.ndarray, labels: dict, inset: float = 1e-3
) -> tuple[list[Quad], list[dict]]:
    """Visible windows and ceiling lamps as emissive quads, other lamps as emissive segments. A
    window segment's pixels' rays are cast onto the walls; the quad is the bounding rectangle, in
    the wall most of them hit, of their hit points. A lamp segment most of whose rays hit the
    ceiling is a ceiling panel: its quad is found the same way on the ceiling, ``inset`` times the
    box's height below it (room_objects leaves such lamps to this stage: no asset is a light flush
    with the ceiling). Any other lamp is an object the object stage places, returned as a
    {"segment", "name"} mark. ``segments``: (H, W) ids at the camera's size; ``labels``: id ->
    (class, name)."""
    rays = pixel_directions(camera)
    walls, ceiling = wall_quads(box), ceiling_quad(box)
    quads, lamps = [], []
    for sid, (cls, name) in sorted(labels.items()):
        if cls not in ("window", "lamp"):
            continue
        directions = rays[segments == sid]
        if cls == "lamp":
            pu, pv = _wall_hits(ceiling, camera.center, directions)
            if len(pu) > len(directions) / 2:
                quads.append(_footprint(ceiling, pu, pv, "lamp", name or f"lamp_{sid}", inset * _size(box)[1]))
            else:
                lamps.append({"segment": int(sid), "name": name or f"lamp_{sid}"})
            continue
        # The wall the window is on: the one most of its pixels' rays hit (a window's pixels
        # straddling a corner keep to the wall of their majority).
        hits = [_wall_hits(wall, camera.center, directions) for wall in walls]
        best = int(np.argmax([len(h[0]) for h in hits]))
        (pu, pv), wall = hits[best], walls[best]
        if len(pu):
            quads.append(_footprint(wall, pu, pv, "window", name or f"window_{sid}"))
    return quads, lamps


@dataclass
class LightSet:
    lights: list[Quad]
    lamps: list[dict] = field(default_factory=list)
    culled: dict = field(default_factory=dict)  # counts of the ceiling cells removed, by reason

    def to_json(self) -> dict:
        return {"lights": [q.to_json() for q in self.lights], "lamps": self.lamps, "culled": self.culled}


def initial_lights(
    box,
    camera: Camera,
    settings: LightSettings | None = None,
    segments: np.ndarray | None = None,
    labels: dict | None = None,
) -> LightSet:
    """The paper's initial light set: the ceiling grid less the cells in the frustum or wholly
    behind the camera, the light behind the camera, one per invisible wall, visible windows."""
    s = settings or LightSettings()
    kept, seen, behind = [], 0, 0
    for quad in ceiling_grid(box, s.cell, s.shrink):
        if in_frustum(quad, camera):
            seen += 1
        elif behind_camera(quad, camera):
            behind += 1
        else:
            kept.append(quad)
    lights = kept + [camera_light(box, camera, s.camera_size, s.camera_offset)]
    lights += invisible_wall_lights(box, camera, s.window_size, s.inset)
    lamps = []
    if segments is not None and labels:
        windows, lamps = window_lights(box, camera, segments, labels, s.inset)
        lights += windows
    return LightSet(lights, lamps, {"in_frustum": seen, "behind_camera": behind})
