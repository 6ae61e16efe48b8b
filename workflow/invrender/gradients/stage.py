"""The `gradients` stage: d(image loss)/d(map) for every parameter map, as EXR + PNG previews.

By default the scene is the state an optimiser starts from: the captured geometry (mesh.ply with
its atlas UVs) with uniform maps, seen by the capture's cameras. The loss is MILO's Eq. 5,
sum_j || L_j - target_j ||_2 over a batch of rays drawn from all pixels of all images.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..render.adjoint import backward, backward_seed, choose_accumulation
from ..render.batches import ray_batch
from ..render.features import Features
from ..render.renderer import Renderer
from ..render.torch_ops import MAP_ORDER
from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import read_cameras
from ..scene.capture import pixel_targets
from ..scene.images import write_exr, write_png_preview
from ..scene.mesh_io import read_mesh
from ..scene.types import Maps, Scene, SceneError, require_positive

log = logging.getLogger(__name__)
# A neutral start in which every map receives a gradient: some light everywhere (ke, and kg
# through kw), so the albedos see light too.
INITIAL = {"kd": 0.5, "ks": 0.04, "ka": 0.1, "ke": 0.1, "kw": 0.1, "kg": 1.0}


def initial_scene(geometry_dir, cameras_path, cube: int = 16, initial: dict = INITIAL) -> Scene:
    """The captured geometry with uniform maps at its atlas resolution, seen by the cameras (a
    COLMAP model or transforms.json)."""
    geometry_dir = Path(geometry_dir)
    mesh = read_mesh(geometry_dir / "mesh.ply")
    with np.load(geometry_dir / "atlas.npz") as atlas:
        size = atlas["mask"].shape
    return Scene(mesh, Maps.uniform(size=size, cube=cube, **initial), read_cameras(cameras_path))


def signed_preview(gradient: np.ndarray) -> np.ndarray:
    """Red for positive, blue for negative d loss / d map (summed over RGB), scaled by the 99th
    percentile of |g|: where raising the map would raise the loss, and where it would lower it."""
    g = gradient if gradient.ndim == 2 else gradient.sum(axis=-1)
    scale = np.percentile(np.abs(g), 99) or 1.0
    g = np.clip(g / scale, -1, 1)
    return np.stack([np.maximum(g, 0), np.zeros_like(g), np.maximum(-g, 0)], -1)


def run(
    geometry_dir,
    cameras_path,
    images_dir,
    out_dir,
    batch: int = 65536,
    spp: int = 16,
    seed: int = 0,
    iteration: int = 0,
    device: str | None = None,
    accumulation: str = "auto",
) -> dict:
    check_output(out_dir, "gradients")  # before the work, not after it
    spp = require_positive("gradients --spp", "samples per pixel", spp)
    batch = require_positive("gradients --batch", "rays per batch", batch)
    scene = initial_scene(geometry_dir, cameras_path)
    if not scene.cameras:
        raise SceneError(cameras_path, "(cameras)", "at least one posed camera")
    total = sum(c.width * c.height for c in scene.cameras)
    requests = ray_batch(scene.cameras, min(batch, total), seed, iteration)
    target = pixel_targets(images_dir, scene.cameras, requests)
    renderer = Renderer(scene, Features.everything(), device=device)
    radiance, _, _ = renderer.render_requests(scene.cameras, requests, spp, seed)
    residual = radiance.astype(np.float64) - target
    norm = np.linalg.norm(residual, axis=1, keepdims=True)
    adjoint = np.where(norm > 0, residual / np.where(norm > 0, norm, 1), 0.0)  # d ||r|| / d L
    accumulation = choose_accumulation(renderer.context.devices[0], accumulation)  # the report names the mode run
    grads = backward(renderer, scene.cameras, requests, adjoint, spp, backward_seed(seed), accumulation)
    report = {
        "loss": float(norm.sum()),
        "rays": len(requests),
        "spp": spp,
        "seed": seed,
        "iteration": iteration,
        "accumulation": accumulation,
        "norms": {name: float(np.linalg.norm(grads[name])) for name in MAP_ORDER},
    }
    log.info("loss %.6g over %d rays; gradient norms %s", report["loss"], len(requests), report["norms"])
    with atomic_dir(Path(out_dir), kind="gradients") as tmp:
        tmp = Path(tmp)
        for name in MAP_ORDER:
            g = grads[name] if name != "kg" else grads[name].reshape(-1, grads[name].shape[2], 3)
            write_exr(tmp / f"{name}.exr", g)
            write_png_preview(tmp / f"{name}.png", signed_preview(g), exposure=1.0)
        (tmp / "gradients.json").write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
    return report
