"""The `bake` stage (`invrender bake`): results/{scene}/scene/ from what was recovered.

A multiview scene's maps come from MILO-Net (the milo stage's maps.npz, on the geometry stage's
atlas); the mesh is the geometry stage's (its UVs are that atlas); the cameras are the cameras
stage's model, held-out views included (render and edit show them too). scene.json's metadata
says where each came from, so a scene directory tells how it was made.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from ..scene.atlas import AtlasTexels
from ..scene.atomic import check_output
from ..scene.cameras import read_cameras
from ..scene.format import write_scene
from ..scene.mesh_io import read_mesh
from ..scene.snapshots import load_snapshot
from ..scene.types import Scene, SceneError

log = logging.getLogger(__name__)


def run(maps_path, geometry_dir, cameras_path, out_dir, training_path=None) -> dict:
    """Write the scene directory `out_dir`; returns its metadata. `training_path`: the milo
    stage's training.json, whose preset, iterations and time go into the metadata."""
    check_output(out_dir, "scene")
    geometry_dir = Path(geometry_dir)
    shape = AtlasTexels.load(geometry_dir / "atlas.npz").shape
    # as trained: milo predicts the charts and their padding, and gives every other texel a valid
    # value (the output kernel's lower bounds), so what was rendered in training is what is baked
    maps, iteration, wall_time = load_snapshot(maps_path, shape)
    cameras = read_cameras(cameras_path)
    if not cameras:
        raise SceneError(cameras_path, "(cameras)", "at least one posed camera")
    metadata = {
        "recovered_by": "invrender milo + bake",
        "maps": str(maps_path),
        "mesh": str(geometry_dir / "mesh.ply"),
        "cameras": str(cameras_path),
        "iteration": iteration,
        "training_seconds": wall_time,
    }
    if training_path is not None:
        training = json.loads(Path(training_path).read_text())
        metadata["training"] = {key: training[key] for key in ("preset", "settings_hash", "atlas_hash", "versions")}
    write_scene(out_dir, Scene(read_mesh(geometry_dir / "mesh.ply"), maps, cameras), metadata)
    log.info("bake: %s (maps of iteration %d, %d cameras) -> %s", maps_path, iteration, len(cameras), out_dir)
    return metadata
