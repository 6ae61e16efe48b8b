"""How well retrieval finds an asset's category and azimuth from one photo-like view.

Each asset is placed in a room-like shot: scaled to its nominal size (x 0.85 to 1.15), at a
random yaw, 2 to 5 m in front of a camera at eye height (1.2 to 1.7 m), aimed near it so the
object is off the image centre, vertical field of view 50 to 70 degrees, 320 x 240 pixels.
Its mask and depth go to ``retrieve``; we count the category of the first match (top-1), of
any of the first three (top-3), the exact asset (top-1), and the azimuth's error modulo the
asset's symmetry when the exact asset is first. ``leave_one_out`` takes the asset itself out of
the library first: the category must then come from its siblings (a new model of a known kind).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Asset
from .raster import look_at_pose, rasterize
from .retrieval import retrieve

__all__ = ["Shot", "photo_shot", "measure"]

WIDTH, HEIGHT = 320, 240


@dataclass
class Shot:
    mask: np.ndarray
    depth: np.ndarray
    focal: float
    azimuth_deg: float  # the truth: from where, in the asset's frame, the camera sees it
    elevation_deg: float


def photo_shot(asset: Asset, rng: np.random.Generator) -> Shot:
    size = asset.nominal_size * rng.uniform(0.85, 1.15)
    yaw = rng.uniform(0, 2 * np.pi)
    distance, eye_height = rng.uniform(2.0, 5.0), rng.uniform(1.2, 1.7)
    c, s = np.cos(yaw), np.sin(yaw)
    rot_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # +z -> (sin yaw, 0, cos yaw)
    world = asset.mesh.positions * size @ rot_y.T + [0.0, 0.0, -distance]
    centre = 0.5 * (world.min(axis=0) + world.max(axis=0))
    fov = np.radians(rng.uniform(50, 70))
    focal = 0.5 * HEIGHT / np.tan(fov / 2)
    # Aim a little off the object so it sits off-centre, as in a photo of a room.
    aim = centre + rng.uniform(-0.25, 0.25, 3) * [distance * WIDTH / HEIGHT, distance, 0] * np.tan(fov / 2)
    eye = np.array([0.0, eye_height, 0.0])
    R, t = look_at_pose(eye, aim)
    depth, _ = rasterize(world @ R.T + t, asset.mesh.faces, (focal, focal), (WIDTH / 2, HEIGHT / 2), (WIDTH, HEIGHT))
    to_camera = eye - centre
    azimuth = np.degrees(np.arctan2(to_camera[0], to_camera[2]) - yaw) % 360.0
    elevation = np.degrees(np.arctan2(to_camera[1], np.hypot(to_camera[0], to_camera[2])))
    return Shot(depth > 0, depth, focal, azimuth, elevation)


def azimuth_error(estimate: float, truth: float, symmetry: int) -> float | None:
    """Degrees, modulo the asset's symmetry; None for a round asset (any azimuth is right)."""
    if symmetry == 0:
        return None
    period = 360.0 / symmetry
    d = (estimate - truth) % period
    return float(min(d, period - d))


def measure(assets: list[Asset], shots_per_asset: int = 3, seed: int = 0, leave_one_out: bool = False, cache_dir=None) -> dict:
    rng = np.random.default_rng(seed)
    top1, top3, exact, errors, confusions = [], [], [], [], []
    for index, asset in enumerate(assets):
        library = assets[:index] + assets[index + 1 :] if leave_one_out else assets
        for _ in range(shots_per_asset):
            shot = photo_shot(asset, rng)
            if shot.mask.sum() < 64:
                continue  # off the image: not a query a segmentation would give
            matches = retrieve(shot.mask, shot.depth, library, k=3, focal=shot.focal, cache_dir=cache_dir)
            top1.append(matches[0].category == asset.category)
            top3.append(any(m.category == asset.category for m in matches))
            exact.append(matches[0].name == asset.name)
            if not top1[-1]:
                confusions.append((asset.name, matches[0].name))
            if exact[-1]:
                error = azimuth_error(matches[0].azimuth_deg, shot.azimuth_deg, asset.symmetry)
                if error is not None:
                    errors.append(error)
    errors = np.array(errors)
    return {
        "queries": len(top1),
        "category_top1": float(np.mean(top1)),
        "category_top3": float(np.mean(top3)),
        "asset_top1": float(np.mean(exact)),
        "azimuth_error_median_deg": float(np.median(errors)) if len(errors) else None,
        "azimuth_within_30deg": float(np.mean(errors <= 30)) if len(errors) else None,
        "confusions": confusions,
    }
