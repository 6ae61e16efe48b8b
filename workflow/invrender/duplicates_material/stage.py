"""The `duplicates-material` stage (rule duplicates_material): the copies' one shared material,
their support's and the sky, recovered from the photograph(s) through the adjoint path tracer
(Structure from Duplicates sections 3.2-3.3, with MILO's material model and renderer).

Reads the geometry stage's shared mesh and atlas, the duplicates stage's poses, the cameras
stage's model (with images/) and the segmentation's instance masks; writes into `out_dir`
(results/{scene}/material/): maps.npz (the shared atlas' maps and kg, scene/snapshots.py's
format), support/mesh.ply + support/maps.npz (config `support: plane`), log.csv, training.json,
figure.png (photograph, re-render, recovered kd), snapshots/, checkpoints/. Every check on the
inputs runs before the directory is touched; it is then filled file by file, each atomically, so
`--resume` finds what a killed run left.
"""

from __future__ import annotations

import json
import logging
import resource
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from ..render.features import Features
from ..render.renderer import Renderer
from ..render.scene_buffers import LUMINANCE
from ..scene import checkpoints
from ..scene.atlas import AtlasTexels
from ..scene.atomic import atomic_path, check_output, claim_dir
from ..scene.cameras import read_cameras
from ..scene.capture import read_view
from ..scene.first_guess import first_guess, seen_texels
from ..scene.images import read_mask, write_png_preview
from ..scene.mesh_io import read_mesh, write_ply
from ..scene.neighbours import neighbour_pairs, sky_neighbour_pairs
from ..scene.packing import pack_scene
from ..scene.poses import placements, read_poses
from ..scene.snapshots import drop_snapshots_after, write_snapshot
from ..scene.training_log import TrainingLog
from ..scene.types import Atlas, SceneError
from .config import resolve, settings_hash
from .material import F0, Ground, TexelMaterial
from .rays import SUPPORT_ID, instance_images, pixel_pools
from .support import below_horizon, first_sky, irradiance_weights, support_mesh, support_object, support_texels
from .train import LOG_COLUMNS, Training

log = logging.getLogger(__name__)
FORMAT = "invrender-duplicates-material-checkpoint"
WRITER = "invrender duplicates-material"
MIN_COVERAGE = 0.01  # the copies' share of a masked image's pixels below which there is too little to learn from


def training_features(settings: dict) -> Features:
    """Sky light only (no emitters, no window texels), the specular lobe, exact visibility."""
    return Features(
        emission=False,
        emitter_sampling=False,
        window=False,
        one_sided=False,
        nee=settings["nee"],
        max_bounces=settings["max_bounces"],
    )


def read_masks(masks_path, cameras) -> list:
    """Per camera its instance-id image, or None: `masks_path` is the photograph's mask (a PNG named
    after it) or a folder of <image stem>.png."""
    masks_path = Path(masks_path)
    files = {masks_path.stem: masks_path} if masks_path.is_file() else {}
    if masks_path.is_dir():
        files = {p.stem: p for p in masks_path.glob("*.png")}
    if not files:
        raise SceneError(
            masks_path, "masks", "an instance-id PNG (segmentation/masks/<image stem>.png) or a folder of them"
        )
    masks = []
    for camera in cameras:
        path = files.get(Path(camera.name).stem)
        ids = None if path is None else read_mask(path)
        if ids is not None and ids.shape != (camera.height, camera.width):
            raise SceneError(
                path, "size", f"the image's {camera.width} x {camera.height}, got {ids.shape[1]} x {ids.shape[0]}"
            )
        masks.append(ids)
    if all(m is None for m in masks):
        names = ", ".join(Path(c.name).stem for c in cameras)
        raise SceneError(masks_path, "masks", f"the mask of one of the images ({names}), named <stem>.png")
    return masks


def check_coverage(masks: list, registered: set[int], masks_path) -> None:
    """A masked image whose registered copies cover under MIN_COVERAGE of its pixels (a copy lost in
    a wide view, or an environment-only photograph) is refused before any work."""
    for ids in masks:
        if ids is None:
            continue
        share = float(np.isin(ids, list(registered)).mean())
        if share < MIN_COVERAGE:
            raise SceneError(
                masks_path,
                "instances",
                f"registered copies covering at least {MIN_COVERAGE:.0%} of the image's pixels, got {share:.2%}",
            )


def _ground(settings: dict, n: int, support, below) -> Ground | None:
    """The rule for the sky below the support's horizon (config.py "ground"), None to leave those
    texels free (then they keep their start: no gradient reaches them)."""
    if support is None or settings["ground"] != "lit":
        return None
    return Ground(below, irradiance_weights(n, support[0]), settings["ground_albedo"])


def run(
    geometry_dir,
    poses_path,
    cameras_path,
    masks_path,
    out_dir,
    preset: str = "ci",
    overrides: dict | None = None,
    resume: str = "never",
    device: str | None = None,
    progress: bool = True,
) -> dict:
    checkpoints.check_resume(resume, "duplicates-material --resume")
    settings = resolve(preset, overrides)
    check_output(out_dir, "duplicates-material")
    texels, copies, cameras, images, masks = _read_inputs(geometry_dir, poses_path, cameras_path, masks_path)
    registered = {c.instance_id for c in copies}

    objects, materials, support = _scene_parts(settings, copies, texels, cameras, images, masks)
    n = settings["sky_resolution"]
    kg = np.ones((6, n, n, 3), np.float32)  # the first guess' uniform white sky
    scene = pack_scene(objects, materials, kg, cameras)
    renderer = Renderer(scene, training_features(settings), device=device)
    pools = pixel_pools(renderer, cameras, images, masks, registered, support is not None)
    seen = _seen(renderer, cameras, masks, copies, texels, support)
    if len(pools.object) == 0:
        raise SceneError(masks_path, "instances", "pixels of the registered copies in the images")
    below = below_horizon(n, None if support is None else support[0])
    if len(pools.support):
        kg = first_sky(n, below, np.median(pools.support_target, 0))
    pairs = {"object": neighbour_pairs(texels, settings["smoothness_radius"])}
    if support is not None:
        pairs["support"] = neighbour_pairs(support[1], settings["smoothness_radius"])
    ground, sky_pairs = _ground(settings, n, support, below), sky_neighbour_pairs(n, below)
    if ground is not None:  # the ground's texels follow the sky: no prior among them
        sky_pairs = sky_pairs[~below.reshape(-1)[sky_pairs].any(1)]

    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(1)  # torch's OpenMP workers would spin beside PoCL's (milo/stage.py measured it)
    pixels = np.concatenate([image.reshape(-1, 3) for image in images])
    median = float(max(np.median(pixels @ LUMINANCE), 1e-3))
    training = Training(
        settings,
        TexelMaterial(materials, kg, pairs, sky_pairs, ground, seen),
        renderer,
        scene.packing,
        cameras,
        pools,
        settings["loss_epsilon"] * median,
    )
    out = claim_dir(out_dir, "duplicates-material")
    digests = (settings_hash(settings), checkpoints.atlas_hash(texels.position, texels.mask))
    state = checkpoints.resume(out / "checkpoints", resume, settings, digests, FORMAT, WRITER)
    if state is not None:
        training.restore(state)
    log.info(
        "duplicates-material: %s preset, %d iterations of %d rays x %d spp, %d bounces; %d copies, %d object and "
        "%d support pixels in %d image(s); support: %s; from %d",
        preset,
        settings["iterations"],
        settings["rays"],
        settings["spp"],
        settings["max_bounces"],
        len(copies),
        len(pools.object),
        len(pools.support),
        len(cameras),
        settings["support"],
        training.iteration,
    )
    drop_snapshots_after(out / "snapshots", training.iteration)
    if training.iteration == 0:  # the start (the first guess) too: what training gained is then measurable
        write_snapshot(out / "snapshots" / "iter_000000.npz", training.material.set_maps("object"), 0, 0.0)
    _loop(training, out, digests, progress)
    return _finish(training, out, digests, preset, support, images, masks)


def _read_inputs(geometry_dir, poses_path, cameras_path, masks_path):
    """The shared mesh's atlas texels, the registered copies, the cameras, their images and masks,
    checked (check_coverage) before any output is touched."""
    geometry_dir, cameras_path = Path(geometry_dir), Path(cameras_path)
    mesh = read_mesh(geometry_dir / "mesh.ply")
    texels = AtlasTexels.load(geometry_dir / "atlas.npz")
    copies = placements(read_poses(poses_path), mesh, "object", where=poses_path)
    if not copies:
        raise SceneError(poses_path, "instances", "at least one registered copy (registered: true)")
    cameras = read_cameras(cameras_path)
    images = [read_view(cameras_path / "images", c) for c in cameras]
    masks = read_masks(masks_path, cameras)
    check_coverage(masks, {c.instance_id for c in copies}, masks_path)
    return texels, copies, cameras, images, masks


def _scene_parts(settings, copies, texels, cameras, images, masks):
    """The copies and (config `support: plane`) the support quad, each set's starting atlas (the
    photograph's colours: scene/first_guess.py, as bake shows them before this stage), and the
    support's (mesh, texels) or None."""
    k = next(i for i, m in enumerate(masks) if m is not None)  # the photograph the segmentation ran on
    camera, photo, ids = cameras[k], images[k], masks[k]
    poses = {c.instance_id: c.transform for c in copies}
    start = first_guess if settings["start"] == "photograph" else _grey
    materials = {"object": start(texels, poses, camera, photo, ids)}
    objects, support = list(copies), None
    if settings["support"] == "plane":
        worlds = [c.mesh.positions.astype(np.float64) @ c.transform[:3, :3].T + c.transform[:3, 3] for c in copies]
        quad = support_mesh(worlds, cameras)
        quad_texels = support_texels(quad, settings["support_resolution"])
        materials["support"] = start(quad_texels, {SUPPORT_ID: np.eye(4)}, camera, photo, ids)
        objects.append(support_object(quad))
        support = (quad, quad_texels)
    return objects, materials, support


def _seen(renderer, cameras, masks, copies, texels, support) -> dict[str, np.ndarray]:
    """Per set, the texels some image shows (first_guess.seen_texels over the images, each with
    its mask or, without one, what the scene's own primary rays hit: rays.instance_images)."""
    ids = instance_images(renderer, cameras, masks)
    poses = {c.instance_id: c.transform for c in copies}
    seen = {"object": np.logical_or.reduce([seen_texels(texels, poses, c, i) for c, i in zip(cameras, ids)])}
    if support is not None:
        whole = {SUPPORT_ID: np.eye(4)}
        seen["support"] = np.logical_or.reduce([seen_texels(support[1], whole, c, i) for c, i in zip(cameras, ids)])
    return seen


def _grey(texels, *_) -> Atlas:
    return Atlas.uniform(texels.shape, kd=0.5, ks=F0, ka=0.1)


def _loop(training: Training, out: Path, digests, progress: bool) -> None:
    s = training.settings
    log_csv = TrainingLog(out / "log.csv", LOG_COLUMNS, resume_from=training.iteration)
    bar = tqdm(
        total=s["iterations"], initial=training.iteration, desc="duplicates-material", unit="it", disable=not progress
    )
    while training.iteration < s["iterations"]:
        row = training.step()
        log_csv.append(row)
        bar.update(1)
        bar.set_postfix(image=f"{row['image']:.4g}", smooth=f"{row['smoothness']:.3g}")
        done = training.iteration
        if done % s["snapshot_every"] == 0 or done == s["iterations"]:
            write_snapshot(
                out / "snapshots" / f"iter_{done:06d}.npz",
                training.material.set_maps("object"),
                done,
                training.wall_time,
            )
        if done % s["checkpoint_every"] == 0 and done < s["iterations"]:
            state = training.state() | {"settings": s, "settings_hash": digests[0], "atlas_hash": digests[1]}
            checkpoints.save(out / "checkpoints", state, FORMAT)
    bar.close()


def _finish(training: Training, out: Path, digests, preset: str, support, images, masks) -> dict:
    material = training.material
    write_snapshot(out / "maps.npz", material.set_maps("object"), training.iteration, training.wall_time)
    if support is not None:
        (out / "support").mkdir(exist_ok=True)
        write_ply(out / "support" / "mesh.ply", support[0])
        write_snapshot(
            out / "support" / "maps.npz", material.set_maps("support"), training.iteration, training.wall_time
        )
    fit = _figure(training, out / "figure.png", images, masks)
    summary = {
        "preset": preset,
        "settings": training.settings,
        "settings_hash": digests[0],
        "atlas_hash": digests[1],
        "iterations": training.iteration,
        "training_seconds": training.wall_time,
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "copies": sum(1 for o in training.renderer.scene.objects if o.material == "object"),
        "pixels": {"object": len(training.pools.object), "support": len(training.pools.support)},
        "support": None if support is None else {"mesh": "support/mesh.ply", "maps": "support/maps.npz"},
        "fit": fit,
        "emitters": "none: the sky kg is the only light",
    }
    with atomic_path(out / "training.json") as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2) + "\n")
    log.info(
        "duplicates-material: %d iterations in %.1f s; maps -> %s",
        training.iteration,
        training.wall_time,
        out / "maps.npz",
    )
    return summary


def _figure(training: Training, path: Path, images, masks) -> dict:
    """figure.png: the photograph, the recovered scene rendered from its camera, and the shared kd
    atlas, side by side; returns the re-render's mean absolute error on the masked object pixels."""
    k = next(i for i, m in enumerate(masks) if m is not None)
    renderer, camera = training.renderer, training.cameras[k]
    renderer.set_maps(training.packed_maps())
    render = renderer.render(camera, spp=training.settings["figure_spp"], seed=1, aovs=False)["radiance"]
    photo, ids = images[k], masks[k]
    on_object = np.isin(ids, [o.instance_id for o in renderer.scene.objects if o.material == "object"])
    error = float(np.abs(render - photo)[on_object].mean())
    kd = training.material.atlases()["object"].kd
    height = photo.shape[0]
    scale = height / kd.shape[0]
    rows = np.minimum((np.arange(height) / scale).astype(int), kd.shape[0] - 1)
    cols = np.minimum((np.arange(round(kd.shape[1] * scale)) / scale).astype(int), kd.shape[1] - 1)
    panel = np.concatenate([photo, render, kd[rows][:, cols] * np.percentile(photo, 99)], axis=1)
    write_png_preview(path, panel)
    return {"object_pixels_mean_abs_error": error, "figure_spp": training.settings["figure_spp"]}
