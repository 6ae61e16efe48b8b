"""The first guess of a duplicates scene's shared atlas: what bake writes until the material stage
has run, and where the material stage starts.

Each texel's colour is the median over the copies that see it of the photograph's radiance there,
under a uniform white sky (kg = 1), so a diffuse texel renders about as the photograph shows it,
shadows and inter-reflections aside.
"""

from __future__ import annotations

import logging

import numpy as np

from .atlas import AtlasTexels, dilate
from .cameras import project_points
from .types import Atlas

__all__ = ["FIRST_GUESS", "SKY_CUBE", "first_guess", "seen_texels"]

log = logging.getLogger(__name__)

FIRST_GUESS = (
    "kd: the photograph's radiance at each texel (median over the copies that see it), a first guess under a "
    "uniform white sky (kg = 1); ks 0.04, ka 0.1: the material stage (duplicates_material) recovers them"
)
SKY_CUBE = 8


def _own_pixels(texels: AtlasTexels, pose: np.ndarray, camera, ids, instance_id: int):
    """Flat indices of the texels this copy shows in the photograph, and their pixels x, y: facing
    the camera, inside the image, on the copy's own pixel (not hidden by a neighbour)."""
    world = texels.position.reshape(-1, 3).astype(np.float64) @ pose[:3, :3].T + pose[:3, 3]
    normal = texels.normal.reshape(-1, 3).astype(np.float64) @ pose[:3, :3].T
    uv = project_points(camera, world)
    ok = texels.mask.reshape(-1) & np.isfinite(uv).all(axis=1)
    ok &= ((world - camera.center) * normal).sum(axis=1) < 0  # facing the camera
    x, y = np.floor(uv[ok]).astype(np.int64).T
    inside = (x >= 0) & (y >= 0) & (x < camera.width) & (y < camera.height)
    rows = np.flatnonzero(ok)[inside]
    x, y = x[inside], y[inside]
    own = ids[y, x] == instance_id
    return rows[own], x[own], y[own]


def _seen_colours(texels: AtlasTexels, pose: np.ndarray, camera, photo, ids, instance_id: int):
    """Per texel, the photograph's colour where this copy shows it (NaN where it does not)."""
    rows, x, y = _own_pixels(texels, pose, camera, ids, instance_id)
    out = np.full((texels.mask.size, 3), np.nan, np.float32)
    out[rows] = photo[y, x]
    return out


def seen_texels(texels: AtlasTexels, poses: dict, camera, ids) -> np.ndarray:
    """(H, W) bool: the texels some copy shows in the photograph (``_own_pixels``)."""
    seen = np.zeros(texels.mask.size, bool)
    for i, T in poses.items():
        seen[_own_pixels(texels, T, camera, ids, i)[0]] = True
    return seen.reshape(texels.shape)


def first_guess(texels: AtlasTexels, poses: dict, camera, photo, ids) -> Atlas:
    samples = np.stack([_seen_colours(texels, T, camera, photo, ids, i) for i, T in poses.items()])
    seen = np.isfinite(samples[..., 0]).any(axis=0)
    kd = np.full((seen.size, 3), 0.5, np.float32)
    with np.errstate(all="ignore"):
        kd[seen] = np.nanmedian(samples[:, seen], axis=0)
    kd = np.clip(kd, 0.0, 1.0).reshape(*texels.shape, 3)
    kd, _ = dilate(kd, seen.reshape(texels.shape), iterations=8)
    log.info(
        "first guess: %.0f %% of the atlas seen by at least one copy", 100 * seen.sum() / max(texels.mask.sum(), 1)
    )
    atlas = Atlas.uniform(texels.shape, kd=0.5, ks=0.04, ka=0.1)
    atlas.kd = kd.astype(np.float32)
    return atlas
