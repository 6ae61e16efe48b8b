"""Room initialisation (PSDR-Room section 4.2): the coarse box from the segmented point cloud.

1. The point cloud: each pixel's depth along its ray (camera frame, OpenCV axes), keeping the
   wall, floor and ceiling pixels after an erosion of each class (its border pixels mix two
   surfaces, or a surface and an object).
2. The floor plane by RANSAC on the floor points (then least squares on the inliers); its
   normal, turned towards the camera, is the world's +Y and the camera's height is its offset.
3. The height: the median height of the ceiling points; with no ceiling in view, 1.2x the
   highest room point (the paper's rule; a high percentile rather than the maximum, which a
   single noisy pixel decides).
4. Rotation and scale from the walls: wall points projected onto the floor, wall lines found
   by sequential RANSAC; the yaw aligns the box's axes with them (a circular mean of their
   directions modulo 90 degrees, weighted by their inliers) and each line found sets the side
   of the box it lies on. A side without a wall line (the wall behind the camera, usually)
   takes the farthest room point in that direction and at least a margin behind the camera,
   so that the camera is inside the room.

All random choices come from one seeded generator: the same input gives the same box.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..scene.cameras import pixel_directions
from ..scene.types import Camera, SceneError
from .box import CEILING, FLOOR, WALL, RoomBox, rotation_y

__all__ = ["CoarseSettings", "CoarseFit", "point_cloud", "fit_plane", "fit_coarse_box", "frame_camera"]


@dataclass
class CoarseSettings:
    erosion: int = 2  # pixels removed from each class's border
    iterations: int = 500  # RANSAC hypotheses per plane or line
    threshold: float = 0.02  # RANSAC inlier distance, in units of the median depth
    min_points: int = 50  # fewest points of a class, or of a wall line, that count
    min_line_fraction: float = 0.05  # a further wall line needs this fraction of the wall points
    max_lines: int = 4
    side_angle_deg: float = 20.0  # a wall line within this of a box axis sets that side
    camera_margin: float = 0.1  # an unseen side lies at least this far behind the camera
    no_ceiling_factor: float = 1.2  # the paper's height with no ceiling in view
    top_percentile: float = 99.5  # "the maximum height point", robust to single pixels

    @classmethod
    def from_overrides(cls, overrides: dict) -> CoarseSettings:
        """The defaults with a user's KEY=VALUE overrides, an unknown key refused by name."""
        known = cls.__dataclass_fields__
        for key, value in overrides.items():
            if key not in known:
                raise SceneError("room-box --coarse", key, f"one of {', '.join(known)}")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                raise SceneError("room-box --coarse", key, f"a number of at least 0, got {value!r}")
        return cls(**overrides)


@dataclass
class CoarseFit:
    box: RoomBox  # in the world frame of `camera`
    camera: Camera  # the photo's camera, posed in that world
    floor: dict  # the floor plane in the camera frame: normal (towards the camera) and offset
    ceiling_seen: bool
    wall_lines: list = field(default_factory=list)  # [{"angle_deg", "offset", "inliers"}] in the world


def point_cloud(depth: np.ndarray, camera: Camera) -> np.ndarray:
    """(H, W, 3) camera-frame points of a depth map (distance along the forward axis)."""
    directions = pixel_directions(_unposed(camera))  # z = 1: scaled by the depth
    return directions * depth[:, :, None]


def _unposed(camera: Camera) -> Camera:
    return Camera(camera.name, camera.model, camera.width, camera.height, camera.params, np.eye(3), np.zeros(3))


def _eroded(classes: np.ndarray, label: int, pixels: int) -> np.ndarray:
    mask = (classes == label).astype(np.uint8)
    if pixels > 0:
        mask = cv2.erode(mask, np.ones((2 * pixels + 1, 2 * pixels + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    return mask.astype(bool)


# RANSAC scores its hypotheses on at most this many of the points (a photo's wall has hundreds of
# thousands): the count of a subset ranks them as well; the final inliers are taken from all.
RANSAC_SUBSET = 20000


def _ransac(points: np.ndarray, rng: np.random.Generator, iterations: int, threshold: float):
    """RANSAC hyperplane (a plane of (N, 3) points, a line of (N, 2) ones) refined by least
    squares on its inliers: (unit normal n, offset c with n.p = c, inlier mask over all points)."""
    dims = points.shape[1]
    subset = points[rng.choice(len(points), min(len(points), RANSAC_SUBSET), replace=False)]
    best_normal, best_offset, best_count = None, 0.0, -1
    for _ in range(iterations):
        sample = subset[rng.choice(len(subset), dims, replace=False)]
        normal = np.linalg.svd(sample[1:] - sample[0])[2][-1]  # orthogonal to the sample's span
        if np.linalg.matrix_rank(sample[1:] - sample[0], tol=1e-9) < dims - 1:
            continue
        count = int((np.abs(subset @ normal - normal @ sample[0]) < threshold).sum())
        if count > best_count:
            best_normal, best_offset, best_count = normal, normal @ sample[0], count
    inliers = np.abs(points @ best_normal - best_offset) < threshold
    centroid = points[inliers].mean(axis=0)
    normal = np.linalg.svd(points[inliers] - centroid, full_matrices=False)[2][-1]
    return normal, normal @ centroid, np.abs(points @ normal - normal @ centroid) < threshold


def fit_plane(points: np.ndarray, rng: np.random.Generator, iterations: int, threshold: float):
    """RANSAC plane of (N, 3) points: (unit normal n, offset d with n.p + d = 0, inlier mask)."""
    normal, offset, inliers = _ransac(points, rng, iterations, threshold)
    return normal, -offset, inliers


def _fit_line(points: np.ndarray, rng: np.random.Generator, iterations: int, threshold: float):
    """RANSAC line of (N, 2) points: (unit normal m, offset c with m.p = c, inlier mask)."""
    return _ransac(points, rng, iterations, threshold)


def frame_camera(camera: Camera, normal: np.ndarray, offset: float) -> tuple[np.ndarray, Camera]:
    """The world of a floor plane (camera frame): +Y its normal, the floor at y = 0, the camera
    above the origin, +X the camera's right along the floor. Returns (M, posed camera) with
    world = M @ camera-frame point + (0, offset, 0)."""
    x = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    if np.linalg.norm(x) < 1e-6:  # looking straight down or up: the camera's forward instead
        x = np.array([0.0, 0.0, 1.0]) - normal[2] * normal
    x /= np.linalg.norm(x)
    M = np.stack([x, normal, np.cross(x, normal)])
    R = M.T  # world-to-camera rotation
    t = -R @ np.array([0.0, offset, 0.0])
    return M, Camera(camera.name, camera.model, camera.width, camera.height, camera.params, R, t)


def _circular_yaw(angles: np.ndarray, weights: np.ndarray) -> float:
    """The yaw (radians, in [-pi/4, pi/4)) whose box axes best align with lines of these
    directions (radians): a weighted mean of 4 * angle on the circle, since a box repeats
    every 90 degrees. A line at angle a is along the box's x axis when yaw = -a."""
    mean = np.angle(np.sum(weights * np.exp(4j * angles)))
    return float(-mean / 4)


def _wall_lines(walls2d: np.ndarray, rng, settings: CoarseSettings, scale: float) -> list:
    lines, remaining = [], walls2d
    least = max(settings.min_points, int(settings.min_line_fraction * len(walls2d)))
    while len(lines) < settings.max_lines and len(remaining) >= least:
        normal, offset, inliers = _fit_line(remaining, rng, settings.iterations, settings.threshold * scale)
        if inliers.sum() < least:
            break
        lines.append((normal, offset, int(inliers.sum()), remaining[inliers]))
        remaining = remaining[~inliers]
    return lines


def fit_coarse_box(
    depth: np.ndarray,
    classes: np.ndarray,
    camera: Camera,
    settings: CoarseSettings,
    seed: int = 0,
    files: dict | None = None,
) -> CoarseFit:
    """The coarse box of a depth map (camera-space z, any scale; 0 = none) and its per-pixel
    classes (BOX_CLASSES indices, -1 elsewhere). ``files`` names the inputs for the errors:
    {"depth": path, "segmentation": path}."""
    files = files or {}
    rng = np.random.default_rng(seed)
    valid = depth > 0
    scale = float(np.median(depth[valid])) if valid.any() else 0.0
    points = point_cloud(depth, camera)
    room = {c: _eroded(classes, c, settings.erosion) & valid for c in (WALL, FLOOR, CEILING)}

    floor_points = points[room[FLOOR]]
    if len(floor_points) < settings.min_points:
        raise SceneError(
            files.get("segmentation", "segmentation"),
            "floor",
            f"at least {settings.min_points} floor pixels with depth after a {settings.erosion}-pixel erosion "
            f"(the floor plane is fitted to them), got {len(floor_points)}",
        )
    normal, offset, inliers = fit_plane(floor_points, rng, settings.iterations, settings.threshold * scale)
    if offset < 0:  # the normal towards the camera (at the origin): n.0 + d > 0
        normal, offset = -normal, -offset
    M, posed = frame_camera(camera, normal, offset)

    def world(mask):
        return points[mask] @ M.T + np.array([0.0, offset, 0.0])

    ceiling_seen = room[CEILING].sum() >= settings.min_points
    all_room = world(room[WALL] | room[FLOOR] | room[CEILING])
    if ceiling_seen:
        height = float(np.median(world(room[CEILING])[:, 1]))
    else:
        height = settings.no_ceiling_factor * float(np.percentile(all_room[:, 1], settings.top_percentile))

    walls2d = world(room[WALL])[:, [0, 2]]
    lines = _wall_lines(walls2d, rng, settings, scale) if len(walls2d) >= settings.min_points else []
    angles = np.array([np.arctan2(-n[0], n[1]) for n, _, _, _ in lines])  # the lines' directions
    yaw = _circular_yaw(angles, np.array([count for _, _, count, _ in lines], np.float64)) if lines else 0.0
    box = _sides(all_room[:, [0, 2]], lines, yaw, height, settings, scale)
    wall_lines = [
        {"angle_deg": round(float(np.degrees(a)), 3), "offset": round(float(o), 6), "inliers": n}
        for a, (_, o, n, _) in zip(angles, lines)
    ]
    floor = {
        "normal": [round(float(v), 6) for v in normal],
        "offset": round(float(offset), 6),
        "inliers": int(inliers.sum()),
        "points": len(floor_points),
    }
    return CoarseFit(box=box, camera=posed, floor=floor, ceiling_seen=bool(ceiling_seen), wall_lines=wall_lines)


def _sides(room2d, lines, yaw, height, settings: CoarseSettings, scale: float) -> RoomBox:
    """The box's horizontal extent in its own axes (u, v) = its x, z: each side from the wall line
    on it with the most inliers, else from the farthest room point, and the camera (the world's
    origin) at least ``camera_margin`` inside either way."""
    to_world = rotation_y(yaw)[[0, 2]][:, [0, 2]]  # box (u, v) -> world (x, z)
    to_box = to_world.T
    cos_limit = np.cos(np.radians(settings.side_angle_deg))
    best: dict[tuple[int, int], tuple[int, float]] = {}
    for normal, _, count, inliers in lines:
        m = to_box @ normal
        axis = int(np.argmax(np.abs(m)))
        if abs(m[axis]) < cos_limit:
            continue
        offset = float(np.median((inliers @ to_box.T)[:, axis]))
        side = 1 if offset > 0 else 0
        if count > best.get((axis, side), (0, 0.0))[0]:
            best[(axis, side)] = (count, offset)
    uv = room2d @ to_box.T
    margin = settings.camera_margin * scale
    lo, hi = np.zeros(2), np.zeros(2)
    for axis in range(2):
        far_lo, far_hi = np.percentile(uv[:, axis], [100 - settings.top_percentile, settings.top_percentile])
        lo[axis] = min(best.get((axis, 0), (0, far_lo))[1], -margin)
        hi[axis] = max(best.get((axis, 1), (0, far_hi))[1], margin)
    center_uv = (lo + hi) / 2
    center_xz = to_world @ center_uv
    center = np.array([center_xz[0], height / 2, center_xz[1]])
    size = np.array([hi[0] - lo[0], height, hi[1] - lo[1]])
    return RoomBox(center, size, np.degrees(yaw))
