"""Retrieval of an asset for a segmented object (PSDR-Room section 4, the object stage) by
descriptors that need no learned weights: the silhouette and the relative depth of the object,
cropped to a square around its mask and averaged down to a GRID x GRID image each, compared
(squared L2) with the same images of every asset rendered from AZIMUTHS x ELEVATIONS.

The depth image is scale-free: (z - median z) / (the crop's side at the median depth, in the
same unit as z), so a depth map of any scale (the paper's median-1 normalisation included) and
an object of any size give the same numbers; a user's depth that is not metric-up-to-scale
(disparity, inverse depth) would not. The views' descriptors are cached per library, in a file
keyed by a hash of every asset's mesh and of these settings.

Azimuth: the direction, about +Y in the asset's frame, from which the camera sees it; 0 is
from +z (the front), 90 from +x. ``yaw_from_view`` turns it into the object's yaw in the room.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from ..scene.atomic import atomic_path
from .asset import Asset
from .raster import look_at_pose, rasterize

__all__ = ["GRID", "AZIMUTHS", "ELEVATIONS", "Match", "describe", "library_descriptors", "retrieve", "yaw_from_view"]

DESCRIPTOR_VERSION = 1
GRID = 32  # descriptor image side (cells)
MARGIN = 0.05  # of the crop's side, on each side of the mask's bounding box
AZIMUTHS = np.arange(0.0, 360.0, 15.0)  # degrees
ELEVATIONS = (10.0, 30.0)  # degrees above the horizon: a camera at eye height, 2 to 5 m away
VIEW_DISTANCE = 3.0  # the library's camera, in units of the asset's largest extent (a room's)
VIEW_SIZE = 64  # pixels: two per descriptor cell
DEPTH_WEIGHT = 1.0  # the depth image's weight against the silhouette's, applied when comparing
BLUR_CELLS = 0.0  # Gaussian blur of both images (sigma, cells): tolerance to a shifted edge
MIN_MASK_PIXELS = 16
DEFAULT_FOV_Y_DEG = 60.0


class Match(NamedTuple):
    name: str
    category: str
    distance: float  # squared L2 between descriptors, over GRID * GRID cells
    azimuth_deg: float  # the best view's, refined between neighbouring azimuths
    elevation_deg: float


# ---------------------------------------------------------------- one image's descriptor


def _square_crop(image: np.ndarray, box: tuple[int, int, int, int], side: int) -> np.ndarray:
    """``image`` cut to a ``side`` x ``side`` square centred on ``box`` (y0, y1, x0, x1), zero
    outside the image."""
    y0, y1, x0, x1 = box
    top, left = (y0 + y1 - side) // 2, (x0 + x1 - side) // 2
    out = np.zeros((side, side), np.float32)
    sy0, sx0 = max(top, 0), max(left, 0)
    sy1, sx1 = min(top + side, image.shape[0]), min(left + side, image.shape[1])
    out[sy0 - top : sy1 - top, sx0 - left : sx1 - left] = image[sy0:sy1, sx0:sx1]
    return out


def describe(mask, depth, focal: float) -> np.ndarray:
    """(2 GRID^2,) float32: the silhouette's coverage and the relative depth (module docstring)
    of one object. ``mask`` (H, W) bool, ``depth`` (H, W) camera-space z of any scale or None
    (silhouette only: the depth half is zero), ``focal`` the vertical focal length in pixels."""
    mask = np.asarray(mask, bool)
    if mask.sum() < MIN_MASK_PIXELS:
        raise ValueError(f"retrieve: the object's mask covers {int(mask.sum())} pixels; at least {MIN_MASK_PIXELS}")
    ys, xs = np.nonzero(mask)
    box = (ys.min(), ys.max() + 1, xs.min(), xs.max() + 1)
    side = int(np.ceil(max(box[1] - box[0], box[3] - box[2]) * (1 + 2 * MARGIN)))
    silhouette = cv2.resize(_square_crop(mask.astype(np.float32), box, side), (GRID, GRID), interpolation=cv2.INTER_AREA)
    relative = np.zeros(GRID * GRID, np.float32)
    if depth is not None:
        depth = np.asarray(depth, np.float64)
        valid = mask & (depth > 0) & np.isfinite(depth)
        if valid.any():
            z_med = float(np.median(depth[valid]))
            # The crop's side at the median depth, in depth's unit: side * z / focal.
            rel = np.where(valid, (depth - z_med) * focal / (z_med * side), 0.0)
            rel = np.clip(rel, -1.0, 1.0).astype(np.float32)
            relative = cv2.resize(_square_crop(rel, box, side), (GRID, GRID), interpolation=cv2.INTER_AREA)
    if BLUR_CELLS > 0:
        silhouette, relative = (cv2.GaussianBlur(np.asarray(x, np.float32).reshape(GRID, GRID), (0, 0), BLUR_CELLS) for x in (silhouette, relative))
    return np.concatenate([silhouette.ravel(), np.ravel(relative)])


# ---------------------------------------------------------------- the library's views


def view_camera(asset: Asset, azimuth_deg: float, elevation_deg: float):
    """(R, t, focal) of the library camera: VIEW_DISTANCE from the asset's bounding-box centre,
    looking at it, the asset filling about 90% of the image."""
    p = asset.mesh.positions
    target = 0.5 * (p.min(axis=0) + p.max(axis=0))
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    eye = target + VIEW_DISTANCE * np.array([np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)])
    R, t = look_at_pose(eye, target)
    radius = 0.5 * np.linalg.norm(p.max(axis=0) - p.min(axis=0))
    focal = 0.45 * VIEW_SIZE * (VIEW_DISTANCE - radius) / radius
    return R, t, focal


def view_descriptors(asset: Asset) -> np.ndarray:
    """(len(ELEVATIONS), len(AZIMUTHS), 2 GRID^2) float32."""
    out = np.zeros((len(ELEVATIONS), len(AZIMUTHS), 2 * GRID * GRID), np.float32)
    c = VIEW_SIZE / 2
    for i, e in enumerate(ELEVATIONS):
        for j, a in enumerate(AZIMUTHS):
            R, t, focal = view_camera(asset, a, e)
            depth, _ = rasterize(asset.mesh.positions @ R.T + t, asset.mesh.faces, (focal, focal), (c, c), (VIEW_SIZE, VIEW_SIZE))
            out[i, j] = describe(depth > 0, depth, focal)
    return out


@dataclass(frozen=True)
class LibraryDescriptors:
    names: tuple[str, ...]
    categories: tuple[str, ...]
    views: np.ndarray  # (assets, elevations, azimuths, 2 GRID^2) float32
    key: str


def _settings() -> bytes:
    return repr((DESCRIPTOR_VERSION, GRID, MARGIN, list(AZIMUTHS), ELEVATIONS, VIEW_DISTANCE, VIEW_SIZE, BLUR_CELLS)).encode()


def asset_key(asset: Asset) -> str:
    """A hash of what the asset's view descriptors depend on: its mesh and the settings."""
    h = hashlib.sha256(_settings())
    h.update(np.ascontiguousarray(asset.mesh.positions, np.float64).tobytes())
    h.update(np.ascontiguousarray(asset.mesh.faces, np.int32).tobytes())
    return h.hexdigest()


def library_key(assets) -> str:
    h = hashlib.sha256()
    for a in assets:
        h.update(f"{a.name}\0{a.category}\0{asset_key(a)}\0".encode())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """Beside the kernel binaries (render/program.py): $INVRENDER_CACHE or ~/.cache/invrender."""
    return Path(os.environ.get("INVRENDER_CACHE") or Path.home() / ".cache" / "invrender") / "assets"


# In-process caches: per asset (a library that differs by one asset renders only that one) and
# per library (a stage's queries against one library share one stack).
_ASSET_VIEWS: dict[str, np.ndarray] = {}
_LIBRARIES: dict[str, LibraryDescriptors] = {}


def _read_cache(path: Path, key: str) -> np.ndarray | None:
    if not path.is_file():
        return None
    try:
        with np.load(path) as stored:
            return stored["views"] if str(stored["key"]) == key else None
    except (OSError, ValueError, KeyError):
        return None  # a damaged cache is rebuilt, not trusted


def library_descriptors(assets, cache_dir=None) -> LibraryDescriptors:
    """Every asset's view descriptors: from memory, from the library's cache file (named by
    the library's hash), or rendered and then cached."""
    assets = list(assets)
    key = library_key(assets)
    if key in _LIBRARIES:
        return _LIBRARIES[key]
    path = Path(cache_dir or default_cache_dir()) / f"descriptors-{key[:24]}.npz"
    views = _read_cache(path, key)
    if views is None:
        keys = [asset_key(a) for a in assets]
        for a, k in zip(assets, keys):
            if k not in _ASSET_VIEWS:
                _ASSET_VIEWS[k] = view_descriptors(a)
        views = np.stack([_ASSET_VIEWS[k] for k in keys])
        try:
            with atomic_path(path) as tmp, open(tmp, "wb") as f:
                np.savez(f, key=key, views=views)
        except OSError:
            pass  # a read-only cache costs only the renders next time
    found = LibraryDescriptors(tuple(a.name for a in assets), tuple(a.category for a in assets), views, key)
    _LIBRARIES[key] = found
    return found


# ---------------------------------------------------------------- the query


def _refined_azimuth(distances: np.ndarray, j: int) -> float:
    """The minimum of the parabola through the best azimuth and its two neighbours (circular)."""
    n = len(distances)
    d0, d1, d2 = distances[(j - 1) % n], distances[j], distances[(j + 1) % n]
    curvature = d0 - 2 * d1 + d2
    offset = 0.5 * (d0 - d2) / curvature if curvature > 0 else 0.0
    step = 360.0 / n
    return float((AZIMUTHS[j] + np.clip(offset, -0.5, 0.5) * step) % 360.0)


def retrieve(mask, depth, assets, k: int = 5, focal: float | None = None, cache_dir=None) -> list[Match]:
    """The ``k`` assets whose views best match the object, best first, each with its best view.

    ``mask`` (H, W) bool and ``depth`` (H, W) (any scale, or None) are the whole photo's, so
    that ``focal`` (the vertical focal length in pixels) defaults to a DEFAULT_FOV_Y_DEG field
    of view over H; for a crop pass the photo's focal.
    """
    mask = np.asarray(mask, bool)
    if focal is None:
        focal = 0.5 * mask.shape[0] / np.tan(np.radians(DEFAULT_FOV_Y_DEG) / 2)
    query = describe(mask, depth, focal)
    lib = library_descriptors(assets, cache_dir)
    half = GRID * GRID
    difference = (lib.views - query) ** 2
    distances = difference[..., :half].sum(axis=-1) + DEPTH_WEIGHT**2 * difference[..., half:].sum(axis=-1)
    best = distances.reshape(len(lib.names), -1).min(axis=1)
    matches = []
    for index in np.argsort(best, kind="stable")[:k]:
        e, j = np.unravel_index(np.argmin(distances[index]), distances[index].shape)
        azimuth = _refined_azimuth(distances[index, e], j)
        matches.append(Match(lib.names[index], lib.categories[index], float(best[index]), azimuth, ELEVATIONS[e]))
    return matches


def yaw_from_view(azimuth_deg: float, object_position, camera_center) -> float:
    """The object's yaw (degrees, about +Y, the asset's +z turned towards (sin yaw, 0, cos yaw))
    that makes the camera see it from ``azimuth_deg`` (a Match's)."""
    d = np.asarray(camera_center, np.float64) - np.asarray(object_position, np.float64)
    return float((np.degrees(np.arctan2(d[0], d[2])) - azimuth_deg) % 360.0)
