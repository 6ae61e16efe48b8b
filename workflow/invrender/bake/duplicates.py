"""A duplicates scene directory: the shared mesh (the geometry stage's, with its atlas) instanced
at every recovered pose, seen by the photograph's camera.

With `--material` (the duplicates-material stage's folder) the atlas, the sky and the support
surface (a quad with its own material set) are the recovered ones. Without it the atlas holds the
first guess (scene/first_guess.py: the photograph's colours under a white sky), which is also
where the material stage starts. scene.json's metadata says which.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..scene.atlas import AtlasTexels
from ..scene.atomic import check_output
from ..scene.cameras import read_cameras
from ..scene.capture import read_view
from ..scene.first_guess import FIRST_GUESS, SKY_CUBE, first_guess
from ..scene.format import write_scene
from ..scene.images import read_mask
from ..scene.mesh_io import read_mesh
from ..scene.packing import pack_scene
from ..scene.poses import placements, read_poses
from ..scene.snapshots import load_snapshot
from ..scene.types import ATLAS_MAPS, Atlas, SceneError, SceneObject

log = logging.getLogger(__name__)


def run(geometry_dir, poses_path, cameras_path, masks_path, out_dir, material_dir=None) -> dict:
    """Write the scene directory `out_dir`; returns its metadata. With `material_dir` (the
    duplicates-material stage's folder) the recovered shared atlas, sky and support; else the
    first guess from the photograph and its mask (`masks_path`)."""
    check_output(out_dir, "scene")
    geometry_dir = Path(geometry_dir)
    mesh = read_mesh(geometry_dir / "mesh.ply")
    texels = AtlasTexels.load(geometry_dir / "atlas.npz")
    doc = read_poses(poses_path)
    cameras = read_cameras(cameras_path)
    objects = placements(doc, mesh, "object", where=poses_path)
    if material_dir is not None:
        materials, kg, support, described = recovered_materials(material_dir, texels.shape)
        objects += support
    else:
        materials = {"object": _first_guess(texels, objects, cameras, cameras_path, masks_path)}
        kg, described = np.ones((6, SKY_CUBE, SKY_CUBE, 3), np.float32), FIRST_GUESS
    scene = pack_scene(objects, materials, kg, cameras)
    metadata = {
        "recovered_by": "invrender duplicates + geometry + "
        + ("duplicates-material + " if material_dir else "")
        + "bake",
        "mesh": str(geometry_dir / "mesh.ply"),
        "poses": str(poses_path),
        "cameras": str(cameras_path),
        "materials": described,
        "copies": sum(1 for o in objects if o.material == "object"),
    }
    write_scene(out_dir, scene, metadata)
    log.info("bake: %d copies of %s -> %s", metadata["copies"], geometry_dir / "mesh.ply", out_dir)
    return metadata


def _first_guess(texels, objects, cameras, cameras_path, masks_path) -> Atlas:
    if len(cameras) != 1:
        raise SceneError(cameras_path, "cameras", f"the photograph's one camera, got {len(cameras)}")
    if masks_path is None:
        raise SceneError("bake --poses", "--masks", "the photograph's instance-id PNG (or --material)")
    camera = cameras[0]
    photo = read_view(Path(cameras_path) / "images", camera)
    ids = read_mask(masks_path)
    if ids.shape != photo.shape[:2]:
        raise SceneError(masks_path, "size", f"the photograph's {photo.shape[1]} x {photo.shape[0]}")
    return first_guess(texels, {o.instance_id: o.transform for o in objects}, camera, photo, ids)


def _atlas(maps) -> Atlas:
    return Atlas(**{name: getattr(maps, name) for name in ATLAS_MAPS})


def recovered_materials(material_dir, atlas_shape):
    """The material stage's maps: ({"object": atlas[, "support": atlas]}, kg, [the support object],
    a sentence for scene.json). The support is a quad in world coordinates (identity transform)."""
    material_dir = Path(material_dir)
    maps, iteration, _ = load_snapshot(material_dir / "maps.npz", atlas_shape)
    materials, support = {"object": _atlas(maps)}, []
    quad = material_dir / "support" / "mesh.ply"
    if quad.exists():
        path = material_dir / "support" / "maps.npz"
        if not path.exists():
            raise SceneError(path, "(file)", "the support's maps beside its mesh.ply")
        with np.load(path) as data:
            shape = data["kd"].shape[:2] if "kd" in data else (0, 0)
        support_maps, _, _ = load_snapshot(path, shape)
        materials["support"] = _atlas(support_maps)
        support.append(SceneObject("support", read_mesh(quad), "support", np.eye(4), instance_id=0))
    described = (
        f"kd, ks, ka of the shared atlas{' and the support' if support else ''} and the sky kg recovered by "
        f"invrender duplicates-material ({iteration} iterations, {material_dir})"
    )
    return materials, maps.kg, support, described
