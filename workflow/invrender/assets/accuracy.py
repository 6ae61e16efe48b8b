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

import cv2
import numpy as np

from ..scene.cameras import look_at
from .asset import Asset
from .raster import rasterize
from .retrieval import library_descriptors, retrieve

__all__ = ["Shot", "photo_shot", "measure"]

WIDTH, HEIGHT = 320, 240


@dataclass
class Shot:
    mask: np.ndarray
    depth: np.ndarray
    focal: float
    azimuth_deg: float  # the truth: from where, in the asset's frame, the camera sees it
    elevation_deg: float
    up: np.ndarray  # the world's up in camera space
    yaw_deg: float  # the asset's yaw in the room
    object_centre: np.ndarray  # its bounding box's centre
    eye: np.ndarray  # the camera's centre


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
    # Aim off the object so it sits anywhere in the middle 60% of the image, as in a photo of a room.
    aim = centre + rng.uniform(-0.3, 0.3, 3) * [distance * WIDTH / HEIGHT, distance, 0] * np.tan(fov / 2)
    eye = np.array([0.0, eye_height, 0.0])
    R, t = look_at(eye, aim)
    depth, _ = rasterize(world @ R.T + t, asset.mesh.faces, (focal, focal), (WIDTH / 2, HEIGHT / 2), (WIDTH, HEIGHT))
    to_camera = eye - centre
    azimuth = np.degrees(np.arctan2(to_camera[0], to_camera[2]) - yaw) % 360.0
    elevation = np.degrees(np.arctan2(to_camera[1], np.hypot(to_camera[0], to_camera[2])))
    return Shot(depth > 0, depth, focal, azimuth, elevation, R[:, 1].copy(), np.degrees(yaw) % 360.0, centre, eye)


def damaged(shot: Shot, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The shot as a photo's inputs would give it: the lowest 0-25% of the mask's rows hidden
    (by a nearer object), its outline moved by a pixel (opened or closed at random), and the
    depth divided by its median (the paper's normalisation) with 2% multiplicative noise."""
    mask = shot.mask.copy()
    rows = np.flatnonzero(mask.any(axis=1))
    mask[rows[0] + int(np.ceil((1 - rng.uniform(0, 0.25)) * len(rows))) :] = False
    kernel = np.ones((3, 3), np.uint8)
    mask = (cv2.erode if rng.random() < 0.5 else cv2.dilate)(mask.astype(np.uint8), kernel) > 0
    depth = shot.depth / np.median(shot.depth[shot.mask]) * (1 + 0.02 * rng.standard_normal(shot.depth.shape))
    # A dilated outline takes its depth from the nearest pixel of the object.
    depth = np.where(shot.mask, depth, cv2.dilate(depth, kernel))
    return mask, np.where(mask, depth, 0.0)


def azimuth_error(estimate: float, truth: float, symmetry: int) -> float | None:
    """Degrees, modulo the asset's symmetry; None for a round asset (any azimuth is right)."""
    if symmetry == 0:
        return None
    period = 360.0 / symmetry
    d = (estimate - truth) % period
    return float(min(d, period - d))


def measure(
    assets: list[Asset],
    shots_per_asset: int = 3,
    seed: int = 0,
    leave_one_out: bool = False,
    cache_dir=None,
    know_up: bool = True,
    damage: bool = False,
) -> dict:
    """``know_up``: retrieval is told the world's up (as the room stage knows it from the floor).
    ``damage``: the query is what a real photo's segmentation and depth give (``damaged``)."""
    rng = np.random.default_rng(seed)
    harm = np.random.default_rng(seed + 1)  # its own stream: the damaged shots are the same shots
    everything = library_descriptors(assets, cache_dir)
    top1, top3, exact, errors, confusions = [], [], [], [], []
    for index, asset in enumerate(assets):
        library = everything.without(index) if leave_one_out else everything
        for _ in range(shots_per_asset):
            shot = photo_shot(asset, rng)
            if shot.mask.sum() < 64:
                continue  # off the image: not a query a segmentation would give
            mask, depth = damaged(shot, harm) if damage else (shot.mask, shot.depth)
            matches = retrieve(mask, depth, library, k=3, focal=shot.focal, up=shot.up if know_up else None)
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
