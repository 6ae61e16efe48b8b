"""A duplicates scene directory: the shared mesh (the geometry stage's, with its atlas) instanced
at every recovered pose, seen by the photograph's camera.

Until the material stage (issue 14) recovers albedo and light, the atlas holds a first guess
that a user can look at and that the material stage can start from: each texel's colour is the
median over the copies that see it of the photograph's radiance there, under a uniform white
sky (kg = 1), so a diffuse texel renders about as the photograph shows it, shadows and
inter-reflections aside. scene.json's metadata says so.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..scene.atlas import AtlasTexels, dilate
from ..scene.atomic import check_output
from ..scene.cameras import project_points, read_cameras
from ..scene.capture import read_view
from ..scene.format import write_scene
from ..scene.images import read_mask
from ..scene.mesh_io import read_mesh
from ..scene.packing import pack_scene
from ..scene.poses import placements, read_poses
from ..scene.types import Atlas, SceneError

log = logging.getLogger(__name__)

FIRST_GUESS = (
    "kd: the photograph's radiance at each texel (median over the copies that see it), a first guess under a "
    "uniform white sky (kg = 1); ks 0.04, ka 0.1: the material stage (issue 14) recovers them"
)
SKY_CUBE = 8


def _seen_colours(texels: AtlasTexels, pose: np.ndarray, camera, photo, ids, instance_id: int):
    """Per texel, the photograph's colour where this copy shows it (NaN where it does not)."""
    world = texels.position.reshape(-1, 3).astype(np.float64) @ pose[:3, :3].T + pose[:3, 3]
    normal = texels.normal.reshape(-1, 3).astype(np.float64) @ pose[:3, :3].T
    uv = project_points(camera, world)
    out = np.full((len(world), 3), np.nan, np.float32)
    ok = texels.mask.reshape(-1) & np.isfinite(uv).all(axis=1)
    ok &= ((world - camera.center) * normal).sum(axis=1) < 0  # facing the camera
    x, y = np.floor(uv[ok]).astype(np.int64).T
    inside = (x >= 0) & (y >= 0) & (x < camera.width) & (y < camera.height)
    rows = np.flatnonzero(ok)[inside]
    x, y = x[inside], y[inside]
    own = ids[y, x] == instance_id  # the copy's own pixel: not hidden by a neighbour
    out[rows[own]] = photo[y[own], x[own]]
    return out


def first_guess(texels: AtlasTexels, poses: dict, camera, photo, ids) -> Atlas:
    samples = np.stack([_seen_colours(texels, T, camera, photo, ids, i) for i, T in poses.items()])
    seen = np.isfinite(samples[..., 0]).any(axis=0)
    kd = np.full((seen.size, 3), 0.5, np.float32)
    with np.errstate(all="ignore"):
        kd[seen] = np.nanmedian(samples[:, seen], axis=0)
    kd = np.clip(kd, 0.0, 1.0).reshape(*texels.shape, 3)
    kd, _ = dilate(kd, seen.reshape(texels.shape), iterations=8)
    log.info("bake: %.0f %% of the atlas seen by at least one copy", 100 * seen.sum() / max(texels.mask.sum(), 1))
    atlas = Atlas.uniform(texels.shape, kd=0.5, ks=0.04, ka=0.1)
    atlas.kd = kd.astype(np.float32)
    return atlas


def run(geometry_dir, poses_path, cameras_path, masks_path, out_dir) -> dict:
    """Write the scene directory `out_dir`; returns its metadata."""
    check_output(out_dir, "scene")
    geometry_dir = Path(geometry_dir)
    mesh = read_mesh(geometry_dir / "mesh.ply")
    texels = AtlasTexels.load(geometry_dir / "atlas.npz")
    doc = read_poses(poses_path)
    cameras = read_cameras(cameras_path)
    if len(cameras) != 1:
        raise SceneError(cameras_path, "cameras", f"the photograph's one camera, got {len(cameras)}")
    camera = cameras[0]
    photo = read_view(Path(cameras_path) / "images", camera)
    ids = read_mask(masks_path)
    if ids.shape != photo.shape[:2]:
        raise SceneError(masks_path, "size", f"the photograph's {photo.shape[1]} x {photo.shape[0]}")
    objects = placements(doc, mesh, "object", where=poses_path)
    atlas = first_guess(texels, {o.instance_id: o.transform for o in objects}, camera, photo, ids)
    kg = np.ones((6, SKY_CUBE, SKY_CUBE, 3), np.float32)
    scene = pack_scene(objects, {"object": atlas}, kg, [camera])
    metadata = {
        "recovered_by": "invrender duplicates + geometry + bake",
        "mesh": str(geometry_dir / "mesh.ply"),
        "poses": str(poses_path),
        "cameras": str(cameras_path),
        "materials": FIRST_GUESS,
        "copies": len(objects),
    }
    write_scene(out_dir, scene, metadata)
    log.info("bake: %d copies of %s -> %s", len(objects), geometry_dir / "mesh.ply", out_dir)
    return metadata
