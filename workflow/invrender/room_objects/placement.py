"""An object placed in the room, its points, its coarse pose and its support (PSDR-Room section
4.3, "Coarse geometry prediction").

A placement is the room generator's (synthesize/room_photo.py, truth/room.json): world =
R_y(yaw) (scale * unit mesh) + position, the unit mesh being the asset's (on y = 0, footprint
centred, largest extent 1), ``position`` its footprint's centre at the height of its support.
So ``scale`` is the object's largest extent, and the renderer's pose vector is
[position, (0, yaw, 0), log scale x 3] (R_y is the axis-angle (0, yaw, 0)).

Lengths here are the room's normalised units (room.json's divided by its ``depth_scale``, the
photo's median depth: the paper's "unit range"); the stage converts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..assets import Asset
from ..assets.raster import render_depth
from ..scene.cameras import pixel_directions
from ..scene.room_photo import yaw_matrix
from ..scene.types import Camera

__all__ = [
    "Placement",
    "Segment",
    "CoarseSettings",
    "segment_points",
    "supports",
    "coarse_placement",
    "label_image",
    "mesh_radius",
]

FLOOR = "floor"
FREE = "free"  # no support found: its height is optimised too


@dataclass
class Placement:
    asset: Asset
    position: np.ndarray  # (3,) footprint centre, y = its support's top
    yaw_deg: float
    scale: float  # the object's largest extent

    def __post_init__(self):
        self.position = np.asarray(self.position, np.float64).reshape(3)
        self.yaw_deg = float(self.yaw_deg)
        self.scale = float(self.scale)

    def pose(self) -> np.ndarray:
        """render/silhouette.py's 9-vector."""
        return np.array([*self.position, 0.0, np.radians(self.yaw_deg), 0.0, *[np.log(self.scale)] * 3])

    def world(self) -> np.ndarray:
        return (self.asset.mesh.positions * self.scale) @ yaw_matrix(self.yaw_deg).T + self.position

    @property
    def top(self) -> float:
        """The height of its top: what an object on it stands on."""
        return float(self.position[1] + self.scale * self.asset.extent[1])


@dataclass
class Segment:
    """One object segment of the photo: its pixels and their points in the room's world."""

    id: int
    cls: str  # "object" or "lamp"
    name: str
    mask: np.ndarray  # (H, W) bool, the segment's pixels
    points: np.ndarray  # (N, 3) world points of its pixels with a depth (eroded), normalised units
    depth: np.ndarray  # (N,) their camera z
    support: str = FLOOR  # "floor", a segment id (as text, truth/room.json's) or "free"
    candidates: list = field(default_factory=list)  # retrieval Matches, best first

    @property
    def centre(self) -> np.ndarray:
        return np.median(self.points, axis=0)

    def height_percentile(self, q: float) -> float:
        return float(np.percentile(self.points[:, 1], q))


@dataclass
class CoarseSettings:
    radius_factor: float = 0.5  # the mesh's radius set to this times the points' (the paper's half)
    yaw_steps: int = 24  # rotations about the floor's normal tried (every 15 degrees)
    floor_distance: float = 0.1  # normalised units: a bottom this near the floor stands on it (the paper's 0.1)
    adjacent_px: float = 20.0  # mask edges this near (pixels of a 1024-wide photo) touch (the paper's 20)
    erosion: int = 1  # pixels taken off each segment before its points are taken (mixed borders)
    scale_steps: int = 13  # ours after the paper's start: scales tried (0 or 1: the paper's alone) ...
    max_growth: float = 8.0  # ... from its scale to this times it
    yaw_tolerance: float = 0.25  # the retrieval's yaw is kept unless another's mask L1 is less by this fraction


def segment_points(mask: np.ndarray, depth: np.ndarray, camera: Camera, erosion: int) -> np.ndarray:
    """(N, 3) world points of the mask's pixels with a depth (camera z), the mask eroded first
    (a border pixel's depth mixes the object and what is behind it); all of them when the erosion
    leaves nothing."""
    inner = mask
    if erosion > 0:
        eroded = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=erosion) > 0
        if (eroded & (depth > 0)).sum() >= 3:
            inner = eroded
    pick = inner & (depth > 0)
    rays = pixel_directions(camera)[pick]
    return camera.center + rays * depth[pick][:, None]


def _near(mask: np.ndarray, other: np.ndarray, pixels: int) -> bool:
    """Whether ``other`` has a pixel within ``pixels`` of ``mask``."""
    size = 2 * max(int(round(pixels)), 1) + 1
    grown = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))) > 0
    return bool((grown & other).any())


def supports(segments: list[Segment], floor_mask: np.ndarray, settings: CoarseSettings) -> None:
    """Each segment's support, the paper's rule: on the floor when the bottom of its points is
    within ``floor_distance`` of the floor and its mask within ``adjacent_px`` of the floor's;
    else on top of the object whose mask is that near and whose top is nearest its bottom (within
    ``floor_distance``, and lower than its centre); else free. Points' bottom and top are robust
    percentiles (2 and 98)."""
    width = floor_mask.shape[1]
    pixels = settings.adjacent_px * width / 1024.0
    for seg in segments:
        bottom = seg.height_percentile(2)
        if bottom < settings.floor_distance and _near(seg.mask, floor_mask, pixels):
            seg.support = FLOOR
            continue
        best, gap = None, settings.floor_distance
        for other in segments:
            if other is seg or other.centre[1] >= seg.centre[1]:
                continue
            top = other.height_percentile(98)
            if abs(top - bottom) < gap and top < seg.centre[1] and _near(seg.mask, other.mask, pixels):
                best, gap = other, abs(top - bottom)
        if best is not None:
            seg.support = str(best.id)
        else:
            seg.support = FLOOR if bottom < settings.floor_distance else FREE


def support_order(segments: list[Segment]) -> list[Segment]:
    """Supports before what stands on them (a cycle, which ``supports`` does not make, is cut)."""
    by_id = {str(s.id): s for s in segments}
    order, seen = [], set()

    def visit(seg, path=()):
        if seg.id in seen:
            return
        if seg.support in by_id and seg.support not in path:
            visit(by_id[seg.support], (*path, str(seg.id)))
        seen.add(seg.id)
        order.append(seg)

    for seg in segments:
        visit(seg)
    return order


def mesh_radius(asset: Asset, samples: int = 2000) -> float:
    """The unit mesh's radius as the paper's point cloud's: the median distance of points spread
    over its surface (by area, seeded) to its bounding-box centre."""
    p, f = asset.mesh.positions, asset.mesh.faces
    tri = p[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(f), samples, p=area / area.sum())
    u, v = rng.random((2, samples))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    points = tri[pick, 0] + u[:, None] * (tri[pick, 1] - tri[pick, 0]) + v[:, None] * (tri[pick, 2] - tri[pick, 0])
    centre = 0.5 * (p.min(axis=0) + p.max(axis=0))
    return float(np.median(np.linalg.norm(points - centre, axis=1)))


def label_image(placements: list[Placement], camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The exact (H, W) index of the placement each pixel centre sees first (-1: none) and its
    depth (0: none), by assets/raster.py's z-buffer: the reference the coarse search and the
    metrics use (not the differentiable renderer)."""
    if not placements:
        return np.full((camera.height, camera.width), -1), np.zeros((camera.height, camera.width))
    worlds = [p.world() for p in placements]
    offsets = np.cumsum([0] + [len(w) for w in worlds[:-1]])
    faces = np.concatenate([p.asset.mesh.faces + o for p, o in zip(placements, offsets)])
    owner = np.repeat(np.arange(len(placements)), [len(p.asset.mesh.faces) for p in placements])
    depth, face = render_depth(np.concatenate(worlds), faces, camera)
    return np.where(face >= 0, owner[np.maximum(face, 0)], -1), depth


def _placed(asset, centre, height, yaw, scale, camera, target_depth) -> tuple[Placement, np.ndarray]:
    """``asset`` at ``yaw`` and ``scale``, its bounding-box centre over ``centre`` (x, z), standing at
    ``height`` (None: its box centred at ``centre``'s height); when ``target_depth`` (the segment's
    median depth) is given, then moved along the horizontal line of sight until its own exact
    median depth is that (the points are the object's front, not its middle). Returns it and its
    exact labels."""
    lo, hi = asset.mesh.positions.min(axis=0), asset.mesh.positions.max(axis=0)
    mid = yaw_matrix(yaw) @ (0.5 * (lo + hi) * scale)  # the bounding box's centre, turned
    y = centre[1] - mid[1] if height is None else height
    place = Placement(asset, [centre[0] - mid[0], y, centre[2] - mid[2]], yaw, scale)
    labels, depth = label_image([place], camera)
    if target_depth is not None and (labels == 0).any():
        sight = place.position - camera.center
        sight[1] = 0.0
        forward = np.asarray(camera.R)[2]  # camera z: a step along the sight line changes it by sight . forward
        gain = float(sight @ forward) / max(float(np.linalg.norm(sight)), 1e-9)
        if gain > 0.1:
            shift = (target_depth - float(np.median(depth[labels == 0]))) / gain
            place.position += shift * sight / np.linalg.norm(sight)
            labels, depth = label_image([place], camera)
    return place, labels


def coarse_placement(
    seg: Segment,
    asset: Asset,
    height: float | None,
    camera: Camera,
    target,
    ignore,
    target_depth,
    settings,
    view_yaw: float | None = None,
) -> tuple[Placement, float]:
    """The coarse pose of ``asset`` for ``seg``. The paper's: its bounding-box centre over the points'
    median (x, z), its radius half the points' (``radius_factor``), standing at ``height`` (its
    support's top; None when free: centred on the points' median height), and the rotation about
    the floor's normal of ``yaw_steps`` whose exact mask has the least mean L1 to ``target`` (the
    segment's block mask at ``camera``'s size) over the pixels not ``ignore``d (another object's,
    which may hide it). Ours after it (docs/room-objects.md: from the paper's start alone the
    refinement did not reach the objects in 40 steps): the scale times each of ``scale_steps``
    (1 to ``max_growth``, geometric) with the object moved back along the line of sight to the
    segment's median depth (``target_depth``), the least mask L1 kept; then the rotations again at
    that scale, where ``view_yaw`` (the retrieval's, from its best view: its depth tells a chair's
    front from its back, which a silhouette does not) is kept unless another's mask L1 is less by
    more than ``yaw_tolerance`` of it; the scales again at a new rotation. Returns the placement
    and its mask L1."""
    centre = seg.centre
    radius = float(np.median(np.linalg.norm(seg.points - centre, axis=1)))
    start = max(settings.radius_factor * radius / mesh_radius(asset), 1e-3)
    keep = ~ignore

    def score(labels) -> float:
        return float(np.abs((labels == 0).astype(np.float64) - target)[keep].mean())

    def tried(yaw, scale, depth):
        place, labels = _placed(asset, centre, height, yaw, scale, camera, depth)
        return score(labels), place

    def best_yaw(scale, depth):
        grid = np.arange(settings.yaw_steps) * 360.0 / settings.yaw_steps
        return min((tried(yaw, scale, depth) for yaw in grid), key=lambda x: x[0])

    def best_scale(yaw, found):
        for growth in np.geomspace(1.0, settings.max_growth, settings.scale_steps):
            found = min(found, tried(yaw, start * growth, target_depth), key=lambda x: x[0])
        return found

    l1, place = best_yaw(start, None)  # the paper's coarse pose
    if settings.scale_steps <= 1:
        return place, l1
    l1, place = best_scale(place.yaw_deg, (l1, place))
    grid = best_yaw(place.scale, target_depth)
    if view_yaw is not None:
        view = tried(view_yaw, place.scale, target_depth)
        if view[0] <= grid[0] * (1 + settings.yaw_tolerance):
            grid = view
    if grid[1].yaw_deg != place.yaw_deg:
        grid = best_scale(grid[1].yaw_deg, grid)
    l1, place = grid
    return place, l1
