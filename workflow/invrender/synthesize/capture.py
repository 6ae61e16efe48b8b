"""Render a synthetic scene into a capture directory: what a user would bring, plus the truth.

    capture/
      images/<view>.exr       rendered radiance, linear RGB float32 (the COLMAP image names)
      images/<view>.png       sRGB previews
      sparse/                 COLMAP text model of the cameras (world-to-camera, OpenCV axes)
      mesh.ply                geometry only (no UVs): the mesh a scanner would give
      ground_truth/scene/     the scene directory (write_scene): mesh with UVs, maps, cameras
      ground_truth/masks/<view>.png  true instance ids from the renderer's instance-id AOV
                              (uint16, 0 = none)
      ground_truth/poses.json duplicates only: true T_obj2world per instance (scene/poses.py)
      ground_truth/object.ply duplicates only: the shared object mesh in its own frame

Everything outside ground_truth/ stands for what a user brings; only an evaluation reads
ground_truth/. The true masks are truth (a user's masks come from a segmentation tool), so they
live there: a test that wants them as a provided segmentation copies them out.

The directory is built beside ``out_dir`` and renamed into place only when complete.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import write_colmap
from ..scene.format import write_scene
from ..scene.images import write_exr, write_mask, write_png_preview
from ..scene.mesh_io import write_ply
from ..scene.poses import write_poses
from ..scene.types import Mesh, Scene

__all__ = ["write_capture", "AOV_SHAPES"]

log = logging.getLogger(__name__)

# What write_capture needs from Renderer.render(camera, spp, seed), per (H, W).
AOV_SHAPES = {"radiance": (3,), "instance_id": ()}


def _default_renderer(scene: Scene, device: str | None = None):
    """The truth is rendered with every effect it calls for (render/analysis.py decides)."""
    from ..render.analysis import analyse
    from ..render.renderer import Renderer

    return Renderer(scene, analyse(scene, device=device), device=device)


def _stem(name: str) -> str:
    return name[: -len(Path(name).suffix)] if Path(name).suffix else name


def write_capture(
    scene: Scene,
    metadata: dict,
    out_dir,
    renderer_factory: Callable[[Scene], object] | None = None,
    spp: int = 64,
    seed: int = 0,
) -> None:
    """Render every camera of ``scene`` and write the capture directory ``out_dir`` atomically.

    ``renderer_factory(scene)`` returns an object with ``render(camera, spp=, seed=)`` giving
    at least 'radiance' (H, W, 3) and 'instance_id' (H, W); default ``invrender.render.Renderer``.
    The renderer keys its random numbers by (seed, ray id) with ray ids distinct across the
    scene's cameras, so one seed serves every view and the noise differs between views.
    Camera names are the COLMAP image names (``view_000.exr``); previews and masks share the stem.
    """
    if not scene.cameras:
        raise ValueError("write_capture: the scene has no cameras to render")
    out_dir = check_output(out_dir, "capture")  # before the work, not after it
    renderer = (renderer_factory or _default_renderer)(scene)
    with atomic_dir(out_dir, kind="capture") as tmp:
        masks = tmp / "ground_truth" / "masks"
        (tmp / "images").mkdir()
        masks.mkdir(parents=True)
        for cam in tqdm(scene.cameras, desc="capture", unit="view"):
            out = renderer.render(cam, spp=spp, seed=seed)
            for key, tail in AOV_SHAPES.items():
                got = np.shape(out[key])
                if got != (cam.height, cam.width, *tail):
                    raise RuntimeError(
                        f"renderer: {key} of {cam.name} has shape {got}, expected {(cam.height, cam.width, *tail)}"
                    )
            radiance = np.asarray(out["radiance"], np.float32)
            if not np.all(np.isfinite(radiance)):
                raise RuntimeError(f"renderer: non-finite radiance in {cam.name}")
            ids = np.asarray(out["instance_id"])
            if ids.min() < 0 or ids.max() > np.iinfo(np.uint16).max:
                raise RuntimeError(f"renderer: instance ids of {cam.name} outside uint16")
            stem = _stem(cam.name)
            write_exr(tmp / "images" / f"{stem}.exr", radiance)
            write_png_preview(tmp / "images" / f"{stem}.png", radiance)
            write_mask(masks / f"{stem}.png", ids.astype(np.uint16))
        write_colmap(tmp / "sparse", [_exr_named(c) for c in scene.cameras])
        write_ply(tmp / "mesh.ply", _scan_mesh(scene.mesh))
        truth = tmp / "ground_truth"
        write_scene(truth / "scene", scene, metadata)
        if "poses" in metadata:
            from .duplicates import object_mesh

            write_poses(truth / "poses.json", metadata["poses"])
            write_ply(truth / "object.ply", object_mesh(scene, metadata))
    log.info("wrote %s: %d views at %d spp", out_dir, len(scene.cameras), spp)


def _scan_mesh(mesh: Mesh) -> Mesh:
    """What a scanner would give: positions and faces only (no atlas, no instance ids), with
    the vertices xatlas split along chart seams welded again. Face order is kept, so face f
    is face f of the ground-truth mesh."""
    positions, inverse = np.unique(np.asarray(mesh.positions, np.float32), axis=0, return_inverse=True)
    return Mesh(positions=positions, faces=inverse.reshape(-1)[mesh.faces].astype(np.int32), uvs=None)


def _exr_named(cam):
    """The camera with its COLMAP image name pointing at the EXR in images/."""
    from dataclasses import replace

    return replace(cam, name=f"{_stem(cam.name)}.exr")
