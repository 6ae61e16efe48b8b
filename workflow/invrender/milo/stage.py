"""The `milo` stage (`invrender milo`, rule milo_train): MILO-Net trained on a capture.

Reads the geometry stage's mesh and atlas, the cameras stage's model and the captured images;
writes into `out_dir` (results/{scene}/milo/): weights.pt (the network, its settings and the
package versions), maps.npz (the six maps it predicts: what `bake` turns into a scene), log.csv
(one row per iteration), snapshots/ (the maps every `snapshot_every` iterations with the
training time, for evaluate's accuracy-against-time curve), checkpoints/ (the newest one).
The directory is filled file by file (each written atomically) so that `--resume` finds what a
killed run left.
"""

from __future__ import annotations

import json
import logging
import platform
import resource
from importlib.metadata import version
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from ..render.features import Features
from ..render.renderer import Renderer, pixel_requests
from ..render.scene_buffers import LUMINANCE
from ..scene.atlas import AtlasTexels
from ..scene.atomic import atomic_path, claim_dir
from ..scene.cameras import read_cameras
from ..scene.capture import read_view
from ..scene.checkpoints import check_resume
from ..scene.mesh_io import read_mesh
from ..scene.snapshots import drop_snapshots_after, write_snapshot
from ..scene.training_log import TrainingLog
from ..scene.types import Camera, Maps, Scene, SceneError
from . import checkpoint
from .config import resolve, settings_hash
from .importance import TexelPixels, emitting_start
from .network import MiloNet
from .reflectance import refine_reflectance
from .sun import find_sun, fit_sun, sun_texel
from .texel_model import TexelMaps
from .texels import Texels
from .train import LOG_COLUMNS, Training, Views
from .window import find_windows

log = logging.getLogger(__name__)
VISIBILITY_STRIDE = 4  # every 4th pixel in x and y decides whether a camera sees the mesh


def split_views(cameras: list[Camera], holdout, cameras_path) -> tuple[list[Camera], list[Camera]]:
    """(training, held-out) cameras; a held-out name that is not a camera is refused."""
    names = {c.name for c in cameras}
    unknown = [name for name in holdout if name not in names]
    if unknown:
        raise SceneError(cameras_path, "holdout", f"names of its cameras ({', '.join(sorted(names))}), got {unknown}")
    train = [c for c in cameras if c.name not in set(holdout)]
    if not train:
        raise SceneError(cameras_path, "holdout", "at least one camera left for training")
    return train, [c for c in cameras if c.name in set(holdout)]


def check_cameras_see_mesh(renderer: Renderer, cameras: list[Camera], cameras_path) -> None:
    """A camera whose pixels all miss the mesh (a wrong pose, other units, another scene) would
    train on sky alone: refused before training, naming it."""
    for index, camera in enumerate(cameras):
        requests = pixel_requests(camera, index)
        keep = (requests[:, 1] % VISIBILITY_STRIDE == 0) & (requests[:, 2] % VISIBILITY_STRIDE == 0)
        hits = renderer.aovs(cameras, requests[keep])["triangle_id"] >= 0
        if not hits.any():
            raise SceneError(
                cameras_path,
                f"camera {camera.name}",
                "a camera that sees the mesh; none of its pixels hits it (a wrong pose, other units, another mesh?)",
            )


def capture_scale(views: Views) -> tuple[float, float]:
    """(emission, sky): the brightest captured radiance (lamps are the brightest things seen) and
    the typical one, the starting radiance of the emitting materials and of the sky."""
    luminance = views.pixels @ LUMINANCE.astype(np.float32)
    return float(max(np.percentile(luminance, 99.9), 1e-3)), float(max(np.median(luminance), 1e-3))


def training_features(settings: dict) -> Features:
    """Every effect the maps can express: the analysis cannot decide what training will find."""
    return Features(one_sided=False, max_bounces=settings["max_bounces"], nee=settings["nee"])


def versions() -> dict:
    packages = ("invrender", "torch", "numpy", "pyopencl")
    return {"python": platform.python_version(), **{name: version(name) for name in packages}}


def run(
    geometry_dir,
    cameras_path,
    images_dir,
    out_dir,
    preset: str = "demo",
    overrides: dict | None = None,
    resume: str = "never",
    device: str | None = None,
    progress: bool = True,
) -> dict:
    check_resume(resume, "milo --resume")
    settings = resolve(preset, overrides)
    geometry_dir, out = Path(geometry_dir), claim_dir(out_dir, "milo")
    atlas = AtlasTexels.load(geometry_dir / "atlas.npz")
    mesh = read_mesh(geometry_dir / "mesh.ply")
    train_cams, _ = split_views(read_cameras(cameras_path), settings["holdout"], cameras_path)
    images = [read_view(images_dir, c) for c in train_cams]
    views = Views.from_images(train_cams, images)
    scene = Scene(mesh, Maps.uniform(size=atlas.shape, cube=settings["sky_resolution"]), train_cams)
    renderer = Renderer(scene, training_features(settings), device=device)
    check_cameras_see_mesh(renderer, train_cams, cameras_path)

    torch.use_deterministic_algorithms(True)
    # One torch thread: its OpenMP workers spin beside PoCL's on the same cores (a 150-iteration
    # run took 31.7 s with two threads, 14.7 s with one, measured on 2 cores).
    torch.set_num_threads(1)
    emission, sky = capture_scale(views)
    texels = Texels.from_atlas(atlas)
    model = MiloNet(settings, emission, sky) if settings["model"] == "network" else TexelMaps(settings, texels, sky)
    training = Training(settings, model, texels, renderer, views, settings["loss_epsilon"] * sky)
    pixels = TexelPixels.build(atlas, renderer, train_cams)
    radiance, seen = pixels.project(images)
    if settings["texture_importance"]:  # section 3.5's texture importance sampling
        renderer.importance = radiance @ LUMINANCE.astype(np.float32)
    emitting = emitting_start(radiance, seen, emission, settings["warm_start_fraction"])
    model.warm_start(texels, emitting, radiance, seen, settings)
    digests = (settings_hash(settings), checkpoint.atlas_hash(atlas.position, atlas.mask))
    state = checkpoint.resume(out / "checkpoints", resume, settings, digests)
    windows = open_daylight(training, pixels, images, radiance, seen, fit=state is None)
    if state is not None:
        training.restore(state)
    elif settings["model"] == "texels" and settings["reflectance_passes"]:
        refine_reflectance(training, pixels, radiance, emitting | windows)
    log.info(
        "milo: %s preset, %d iterations of %d rays x %d spp, %d bounces; %d texels, %d training views; from %d",
        preset,
        settings["iterations"],
        settings["rays"],
        settings["spp"],
        settings["max_bounces"],
        len(training.texels),
        len(train_cams),
        training.iteration,
    )
    drop_snapshots_after(out / "snapshots", training.iteration)
    _loop(training, out, digests, progress)
    return _finish(training, out, digests, preset, emission, sky)


def open_daylight(training: Training, pixels: TexelPixels, images, radiance, seen, fit: bool) -> np.ndarray:
    """The texels model's daylight: kw = 1 on the windows the photographs show the sky through
    (window.py), the sun that lights the patch they let in (sun.py; its radiance fitted when
    `fit`, else the checkpoint's). Returns the window texels, (H, W) bool."""
    s, model = training.settings, training.net
    windows = None
    if s["model"] == "texels" and s["windows"]:
        windows = find_windows(pixels, images, training.views.cameras, s["sky_resolution"])
    if windows is None:
        return np.zeros(pixels.atlas.shape, bool)
    model.open_windows(training.texels, windows)
    sun = find_sun(pixels, windows, radiance, seen)
    if sun is not None and fit:
        fit_sun(training, pixels, radiance, sun, sun_texel(sun, s))
    elif sun is not None:
        model.light_sun(sun_texel(sun, s), None)
    return windows.texels


def _loop(training: Training, out: Path, digests, progress: bool) -> None:
    s = training.settings
    log_csv = TrainingLog(out / "log.csv", LOG_COLUMNS, resume_from=training.iteration)
    bar = tqdm(total=s["iterations"], initial=training.iteration, desc="milo", unit="it", disable=not progress)
    while training.iteration < s["iterations"]:
        row = training.step()
        log_csv.append(row)
        bar.update(1)
        bar.set_postfix(image=f"{row['image']:.4g}", cat=f"{row['category']:.3g}", tex=f"{row['texture']:.3g}")
        done = training.iteration
        if done % s["snapshot_every"] == 0 or done == s["iterations"]:
            write_snapshot(out / "snapshots" / f"iter_{done:06d}.npz", training.predict(), done, training.wall_time)
        if done % s["checkpoint_every"] == 0 and done < s["iterations"]:
            state = training.state() | {"settings": s, "settings_hash": digests[0], "atlas_hash": digests[1]}
            checkpoint.save(out / "checkpoints", state)
    bar.close()


def _finish(training: Training, out: Path, digests, preset: str, emission: float, sky: float) -> dict:
    maps = training.predict()
    write_snapshot(out / "maps.npz", maps, training.iteration, training.wall_time)
    summary = {
        "preset": preset,
        "settings": training.settings,
        "settings_hash": digests[0],
        "atlas_hash": digests[1],
        "iterations": training.iteration,
        "training_seconds": training.wall_time,
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "texels": len(training.texels),
        "start": {"emission": emission, "sky": sky},
        "versions": versions(),
    }
    with atomic_path(out / "weights.pt") as tmp:
        torch.save({"network": training.net.state_dict(), **summary}, tmp)
    with atomic_path(out / "training.json") as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2) + "\n")
    log.info("milo: %d iterations in %.1f s; maps -> %s", training.iteration, training.wall_time, out / "maps.npz")
    return summary
