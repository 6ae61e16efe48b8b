"""Small synthetic duplicates captures with their truth, and the material stage's inputs built from
the TRUE poses and the TRUE shared mesh (its atlas rasterised at the truth's resolution, so a
recovered texel and the truth texel at the same (row, col) are the same surface point).

The sky is uniform white (kg = 1, no sun): the truth light is then known, and what the stage
must recover is the albedo behind the shading (the floor hides the lower half of the sky, the
copies shadow and light each other), starting from grey."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from invrender.scene.atlas import rasterize_atlas
from invrender.scene.images import read_image
from invrender.scene.mesh_io import read_mesh, write_ply

ATLAS = 96
WHITE_SKY = {
    "sky_zenith": [1.0, 1.0, 1.0],
    "sky_horizon": [1.0, 1.0, 1.0],
    "ground": [1.0, 1.0, 1.0],
    "sun_radiance": [1.0, 1.0, 1.0],
    "size": 4,
}


def capture_config(count: int) -> dict:
    """box-6-ci's copies at 160 x 120, the first `count` of them, none touching."""
    return {
        "preset": "box-6-ci",
        "count": count,
        "camera": {"width": 160, "height": 120},
        "placement": {"touching": 0, "margin_px": 2},
        "atlas_resolution": ATLAS,
        "environment": WHITE_SKY,
    }


def material_inputs(capture: Path, root: Path) -> dict:
    """geometry/ (the truth's object.ply and its atlas), cameras/ (the capture's model with
    images/), the truth poses and mask: the stage's arguments."""
    mesh = read_mesh(capture / "ground_truth" / "object.ply")
    (root / "geometry").mkdir(parents=True)
    write_ply(root / "geometry" / "mesh.ply", mesh)
    rasterize_atlas(mesh, ATLAS, ATLAS).save(root / "geometry" / "atlas.npz")
    shutil.copytree(capture / "sparse", root / "cameras")
    shutil.copytree(capture / "images", root / "cameras" / "images")
    return {
        "geometry_dir": root / "geometry",
        "poses_path": capture / "ground_truth" / "poses.json",
        "cameras_path": root / "cameras",
        "masks_path": capture / "ground_truth" / "masks" / "view_000.png",
    }


def truth_kd(capture: Path) -> np.ndarray:
    return read_image(capture / "ground_truth" / "scene" / "maps" / "kd.exr")[..., :3]


def kd_rmse(kd: np.ndarray, capture: Path, mask: np.ndarray) -> float:
    """Root mean square kd error over the object's texels (the same atlas as the truth's)."""
    return float(np.sqrt(np.mean((kd[mask] - truth_kd(capture)[mask]) ** 2)))
