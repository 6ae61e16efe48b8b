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

import numpy as np

from ..scene.atlas import AtlasTexels, dilate
from ..scene.atomic import check_output
from ..scene.cameras import read_cameras
from ..scene.format import write_scene
from ..scene.mesh_io import read_mesh
from ..scene.snapshots import load_snapshot
from ..scene.types import ATLAS_MAPS, Maps, Scene, SceneError

log = logging.getLogger(__name__)
SEAM_TEXELS = 4  # covered values grown this far into the empty texels around each chart


def run(maps_path, geometry_dir, cameras_path, out_dir, training_path=None) -> dict:
    """Write the scene directory `out_dir`; returns its metadata. `training_path`: the milo
    stage's training.json, whose preset, iterations and time go into the metadata."""
    check_output(out_dir, "scene")
    geometry_dir = Path(geometry_dir)
    mask = AtlasTexels.load(geometry_dir / "atlas.npz").mask
    maps, iteration, wall_time = load_snapshot(maps_path, mask.shape)
    maps = fill_uncovered(maps, mask)
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


def fill_uncovered(maps: Maps, mask: np.ndarray) -> Maps:
    """MILO-Net predicts covered texels only (the rest are 0, and ka = 0 is no valid
    roughness). The nearest-texel lookup can read a texel just outside a chart, so the charts
    are grown into their borders (as the truth's maps are, ``scene.atlas.bake``); texels no
    chart reaches take the mean of the covered ones, a valid value that nothing renders."""
    filled = {}
    for name in ATLAS_MAPS:
        values, grown = dilate(getattr(maps, name), mask, SEAM_TEXELS)
        values[~grown] = values[mask].mean(axis=0)
        filled[name] = values
    return Maps(**filled, kg=maps.kg)
