"""The `evaluate` stage: a recovered scene against the truth (MILO section 4).

    out_dir/metrics.json           every number below (docs/evaluate.md lists the keys)
    out_dir/maps_<map>.png         recovered | truth at the same surface points | |error|
    out_dir/novel_<view>.png       held-out view: render of the recovered scene | capture | |error|
    out_dir/insertion_<view>.png   spheres inserted: recovered scene | truth | |error|
    out_dir/accuracy_vs_time.png   with snapshots: map errors and PSNR against minutes of training

1. Maps on the surface (``correspond.py``, ``maps.py``): light maps MSE, material MSE (shading
   balls), and each map's MSE.
2. Novel views (``views.py``): the recovered scene rendered at the held-out cameras against the
   captured images: PSNR, SSIM, NCC, MSE.
3. Virtual object insertion (``views.py``, Table 3): three spheres in both scenes, rendered from
   the held-out cameras (all cameras if none are held out), one against the other.
4. Accuracy against training time (``snapshots.py``): 1. for every snapshot, and the novel-view
   PSNR at ``snapshot_spp`` (0: not rendered).

A duplicates scene has other outputs and other metrics: ``run_duplicates`` scores its
masks, poses and shared mesh (``duplicates.py``) into the same layout (metrics.json, outlines_<image>.png),
and with its recovered scene directory the shared material, the sky and relighting (SfD Tables 1 and 2,
``appearance.py``, ``relight.py``).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..scene.atlas import AtlasTexels
from ..scene.atomic import atomic_dir, check_output
from ..scene.capture import read_view
from ..scene.format import SCENE_JSON, load_scene
from ..scene.snapshots import check_snapshot, list_snapshots, load_snapshot
from ..scene.types import ATLAS_MAPS, Scene, SceneError, require_positive
from . import appearance, duplicates, figures
from .correspond import DEFAULT_SAMPLES, DEFAULT_SIDE_MARGIN, correspond
from .maps import DEFAULT_BALL_TEXELS, kg_on_common_cube, map_errors, truth_in_recovered_layout
from .metrics import PSNR_CAP_DB, image_metrics
from .views import DEFAULT_RADIUS_FRACTION, insertion, novel_views, place_spheres, render_views

__all__ = ["run", "run_duplicates", "PAPER", "METRICS_VERSION"]

log = logging.getLogger(__name__)

METRICS_VERSION = 1
# MILO (TVCG 2023), section 4.1 and Table 3, on its synthetic scenes.
PAPER = {
    "light_maps_mse": 0.002,
    "material_mse": 0.015,
    "insertion": {"psnr_db": 26.49, "ssim": 0.964, "ncc": 0.978, "mse": 0.002},
}
TONE_MAPPING = (
    "exposure from the reference image (its 99th percentile of the largest channel maps to 1), "
    "the same for both images; clipped to [0, 1]; sRGB-encoded; metrics on [0, 1] values"
)
DEFAULT_SNAPSHOT_SPP = 4


def run(
    scene_dir,
    truth_dir,
    atlas_path,
    images_dir,
    out_dir,
    holdout=(),
    snapshots_dir=None,
    spp=64,
    seed=0,
    device=None,
    placement: list[dict] | None = None,
    radius_fraction: float = DEFAULT_RADIUS_FRACTION,
    snapshot_spp: int = DEFAULT_SNAPSHOT_SPP,
    max_ball_texels: int | None = DEFAULT_BALL_TEXELS,
    side_margin: float = DEFAULT_SIDE_MARGIN,
    progress: bool = True,
) -> dict:
    """Evaluate the recovered scene ``scene_dir`` (its atlas ``atlas_path``) against the truth
    scene ``truth_dir``; write ``out_dir`` (module docstring); return metrics.json's document.

    ``holdout``: camera names of the recovered scene held back from training, compared with
    their images in ``images_dir``. ``placement``: the inserted spheres, [{"kind": "diffuse" |
    "specular" | "emitting", "center": [x, y, z], "radius": r}] (materials from
    ``views.SPHERES`` unless a "material" is given); None places them automatically.
    """
    out_dir = Path(out_dir)
    check_output(out_dir, "evaluate")  # before the work, not after it
    spp = require_positive("evaluate --spp", "samples per pixel", spp)
    snapshot_spp = require_positive("evaluate snapshot_spp", "samples per pixel", snapshot_spp, minimum=0)
    started = time.perf_counter()
    recovered, truth = load_scene(scene_dir), load_scene(truth_dir)
    texels = AtlasTexels.load(atlas_path)
    if tuple(texels.shape) != tuple(recovered.maps.atlas_shape):
        raise SceneError(
            atlas_path,
            "shape",
            f"the recovered scene's atlas size {tuple(recovered.maps.atlas_shape)}, got {tuple(texels.shape)}",
        )
    if not texels.mask.any():
        raise SceneError(atlas_path, "mask", "at least one covered texel")
    held_out = _cameras(recovered, scene_dir, holdout)
    views = held_out or list(recovered.cameras)
    if not views:
        raise SceneError(Path(scene_dir) / SCENE_JSON, "cameras", "cameras to render the inserted objects from")
    for camera in views:  # every image there and of its camera's size, before any work
        read_view(images_dir, camera)
    snapshots = list_snapshots(snapshots_dir) if snapshots_dir is not None else []
    for path in snapshots:
        check_snapshot(path, recovered.maps.atlas_shape)
    placement = _placement(placement) if placement is not None else None
    timings = {}

    t0 = time.perf_counter()
    corr = correspond(texels, truth.mesh, truth.maps.atlas_shape, DEFAULT_SAMPLES, side_margin, recovered.mesh)
    maps = map_errors(recovered.maps, truth.maps, corr, max_ball_texels)
    maps["correspondence"] = corr.summary()
    timings["maps"] = time.perf_counter() - t0
    log.info(
        "maps: light maps MSE %.4g (a constant guess %.4g, paper %.3g), material MSE %.4g (a constant guess %.4g, "
        "paper %.3g)",
        maps["light_maps_mse"],
        maps["constant_guess"]["light_maps_mse"],
        PAPER["light_maps_mse"],
        maps["material_mse"],
        maps["constant_guess"]["material_mse"],
        PAPER["material_mse"],
    )

    with atomic_dir(out_dir, kind="evaluate") as tmp:
        tmp = Path(tmp)
        _map_figures(tmp, recovered, truth, corr)

        novel = None
        if held_out:
            t0 = time.perf_counter()
            novel, pairs = novel_views(recovered, truth, held_out, images_dir, spp, seed, device)
            novel["spp"] = spp
            for name, (render, captured) in pairs.items():
                exposure = novel["views"][name]["exposure"]
                figures.render_figure(
                    tmp / f"novel_{Path(name).stem}.png", render, captured, ("render", "capture"), exposure
                )
            timings["novel_views"] = time.perf_counter() - t0
            log.info("novel views: PSNR %.2f dB, SSIM %.4f", novel["mean"]["psnr_db"], novel["mean"]["ssim"])

        t0 = time.perf_counter()
        spheres = placement or place_spheres(truth, views[0], radius_fraction, device)
        inserted, pairs = insertion(recovered, truth, views, spheres, spp, seed, images_dir, device)
        inserted.update({"spp": spp, "spheres": spheres, "placement": "given" if placement else "automatic"})
        for name, (ours, reference) in pairs.items():
            exposure = inserted["views"][name]["exposure"]
            figures.render_figure(
                tmp / f"insertion_{Path(name).stem}.png",
                ours,
                reference,
                ("recovered + spheres", "truth + spheres"),
                exposure,
            )
        timings["insertion"] = time.perf_counter() - t0
        log.info(
            "insertion: PSNR %.2f dB, SSIM %.4f, NCC %.4f, MSE %.4g",
            *(inserted["mean"][k] for k in ("psnr_db", "ssim", "ncc", "mse")),
        )

        training = None
        if snapshots:
            t0 = time.perf_counter()
            training = _training_table(
                snapshots,
                recovered,
                truth,
                corr,
                held_out,
                images_dir,
                snapshot_spp,
                seed,
                device,
                max_ball_texels,
                progress,
            )
            figures.accuracy_plot(
                tmp / "accuracy_vs_time.png",
                training,
                {k: PAPER[k] for k in ("light_maps_mse", "material_mse")},
            )
            timings["snapshots"] = time.perf_counter() - t0

        document = {
            "version": METRICS_VERSION,
            "inputs": {
                "scene": str(scene_dir),
                "truth": str(truth_dir),
                "atlas": str(atlas_path),
                "images": str(images_dir),
                "holdout": [c.name for c in held_out],
                "snapshots": None if snapshots_dir is None else str(snapshots_dir),
                "spp": spp,
                "seed": int(seed),
            },
            "paper": PAPER,
            "tone_mapping": TONE_MAPPING,
            "psnr_cap_db": PSNR_CAP_DB,
            "maps": maps,
            "novel_views": novel,
            "insertion": inserted,
            "training": training,
        }
        (tmp / "metrics.json").write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    timings["total"] = time.perf_counter() - started
    log.info("evaluate: wrote %s in %.1f s (%s)", out_dir, timings["total"], _seconds(timings))
    return document


def run_duplicates(
    segmentation_dir,
    duplicates_dir,
    truth_dir,
    images_dir,
    out_dir,
    seed: int = 0,
    scene_dir=None,
    training=None,
    spp: int = 64,
    device=None,
) -> dict:
    """Evaluate a duplicates scene: the segment stage's ``segmentation_dir`` (masks/, instances.json)
    and the duplicates stage's ``duplicates_dir`` (poses.json, poses_colmap.json if there,
    object.ply) against the capture's ``truth_dir`` (its ground_truth/); ``images_dir`` holds
    the segmented photo (None: the figure on grey). With the recovered ``scene_dir`` also its
    appearance (``appearance.py``: albedo, roughness, sky, relighting at ``spp``), and the material
    stage's time and memory from ``training`` (its training.json) when that file exists. Writes
    ``out_dir`` (metrics.json, outlines_<image>.png, the appearance figures) and returns
    metrics.json's document (docs/evaluate.md, "Duplicates")."""
    from ..scene.images import read_image

    out_dir = Path(out_dir)
    check_output(out_dir, "evaluate")  # before the work, not after it
    spp = require_positive("evaluate --spp", "samples per pixel", spp)
    started = time.perf_counter()
    inputs = duplicates.load_inputs(segmentation_dir, duplicates_dir, truth_dir)
    sides = None
    if scene_dir is not None:  # read and checked before any work
        sides = (appearance.recovered_side(scene_dir), appearance.truth_side(truth_dir))
        appearance.check_sides(*sides)
    cost = appearance.read_training(training)
    photo = None
    if images_dir is not None:
        path = Path(images_dir) / Path(inputs["image"]).name
        photo = read_image(path)[..., :3]
        if photo.shape[:2] != inputs["truth_ids"].shape:
            h, w = inputs["truth_ids"].shape
            raise SceneError(path, "size", f"{w} x {h} as the masks, got {photo.shape[1]} x {photo.shape[0]}")
    metrics = duplicates.evaluate(inputs, seed)
    with atomic_dir(out_dir, kind="evaluate") as tmp:
        masks = metrics["masks"]
        note = f"mean IoU {masks['mean_iou']:.3f}, {masks['matched']} of {metrics['counts']['truth']} matched"
        duplicates.outline_figure(
            Path(tmp) / f"outlines_{inputs['stem']}.png", photo, inputs["truth_ids"], inputs["recovered_ids"], note
        )
        look = None
        if sides is not None:
            alignment = appearance.Alignment.from_metrics(metrics)
            look = appearance.evaluate(*sides, alignment, tmp, spp, seed, device, metrics["mesh"], cost)
        document = {
            "version": METRICS_VERSION,
            "mode": "duplicates",
            "inputs": {
                "segmentation": str(segmentation_dir),
                "duplicates": str(duplicates_dir),
                "truth": str(truth_dir),
                "images": None if images_dir is None else str(images_dir),
                "image": inputs["image"],
                "seed": int(seed),
                "scene": None if scene_dir is None else str(scene_dir),
                "training": None if training is None else str(training),
                "spp": spp,
            },
            "paper": {"table2_color_box": duplicates.PAPER_TABLE2},
            **metrics,
            "appearance": look,
        }
        (Path(tmp) / "metrics.json").write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    log.info(
        "evaluate (duplicates): %s; wrote %s in %.1f s",
        _duplicates_line(document),
        out_dir,
        time.perf_counter() - started,
    )
    return document


def _duplicates_line(document: dict) -> str:
    """The headline numbers of a duplicates evaluation, for the log."""
    counts, after, mesh = document["counts"], document["poses"]["after"], document["mesh"]
    parts = [
        f"mean IoU {document['masks']['mean_iou']:.3f}",
        f"registered {counts['registered']['after']} of {counts['truth']}",
    ]
    if after["rotation"] is not None:
        error = after["rotation"]["error_deg"]
        parts.append(f"rotation {error['mean']:.3f} deg mean, {error['median']:.3f} median")
    if after["translation"] is not None:
        parts.append(f"translation {after['translation']['error_fraction_of_diagonal']['mean']:.4f} of the diagonal")
    if mesh is not None:
        parts.append(f"Chamfer {mesh['chamfer_m']:.4g} m ({mesh['icp']['chamfer_m']:.4g} after ICP)")
    look = document.get("appearance")
    if look is not None:
        ours = look["table1"]["ours"]
        parts += [f"{key} {value:.4g}" for key, value in ours.items() if value is not None and "chamfer" not in key]
    return ", ".join(parts)


def _seconds(timings: dict) -> str:
    return ", ".join(f"{k} {v:.1f} s" for k, v in timings.items() if k != "total")


def _cameras(scene: Scene, scene_dir, names) -> list:
    """The named cameras of the recovered scene, in the order given; unknown names refused."""
    by_name = {c.name: c for c in scene.cameras}
    missing = [n for n in names if n not in by_name]
    if missing:
        have = ", ".join(list(by_name)[:5]) or "none"
        raise SceneError(
            Path(scene_dir) / SCENE_JSON, "cameras", f"a camera named {', '.join(missing)} (--holdout); it has {have}"
        )
    return [by_name[n] for n in dict.fromkeys(names)]


def _placement(placement: list[dict]) -> list[dict]:
    """Caller-given spheres, checked: a known kind, a finite centre, a positive radius."""
    from .views import SPHERES

    where = "evaluate placement"
    out = []
    for k, sphere in enumerate(placement):
        kind = sphere.get("kind")
        if kind not in SPHERES:
            raise SceneError(where, f"[{k}].kind", f"one of {sorted(SPHERES)}, got {kind!r}")
        center = np.asarray(sphere.get("center", ()), np.float64)
        radius = sphere.get("radius")
        if center.shape != (3,) or not np.all(np.isfinite(center)):
            raise SceneError(where, f"[{k}].center", f"three finite numbers, got {sphere.get('center')!r}")
        if not isinstance(radius, (int, float)) or not np.isfinite(radius) or radius <= 0:
            raise SceneError(where, f"[{k}].radius", f"a positive number of meters, got {radius!r}")
        out.append(
            {
                "kind": kind,
                "material": sphere.get("material", SPHERES[kind]),
                "center": center.tolist(),
                "radius": float(radius),
            }
        )
    return out


def _map_figures(out: Path, recovered: Scene, truth: Scene, corr) -> None:
    truth_here = truth_in_recovered_layout(truth.maps, corr)
    for name in ATLAS_MAPS:
        figures.map_figure(out / f"maps_{name}.png", name, getattr(recovered.maps, name), truth_here[name], corr.mask)
    kg_recovered, kg_truth, _ = kg_on_common_cube(recovered.maps.kg, truth.maps.kg)
    figures.kg_figure(out / "maps_kg.png", kg_recovered, kg_truth)


def _training_table(snapshots, recovered, truth, corr, held_out, images_dir, spp, seed, device, ball_texels, progress):
    """One row per snapshot: iteration, wall time, the map errors, and (held-out views and spp > 0)
    the novel-view PSNR with the seconds its renders took."""
    captured = {c.name: read_view(images_dir, c) for c in held_out} if spp else {}
    table = []
    for path in tqdm(snapshots, desc="snapshots", unit="snapshot", disable=not progress, leave=False):
        maps, iteration, wall_time = load_snapshot(path, recovered.maps.atlas_shape)
        errors = map_errors(maps, truth.maps, corr, ball_texels, constant_guess=False)
        row = {
            "snapshot": path.name,
            "iteration": iteration,
            "wall_time_s": wall_time,
            "light_maps_mse": errors["light_maps_mse"],
            "material_mse": errors["material_mse"],
            "map_mse": errors["map_mse"],
        }
        if captured:
            t0 = time.perf_counter()
            scene = Scene(mesh=recovered.mesh, maps=maps, cameras=recovered.cameras)
            renders = render_views(scene, held_out, spp, seed, device)
            psnr = [image_metrics(renders[name], image)["psnr_db"] for name, image in captured.items()]
            row["novel_view_psnr_db"] = float(np.mean(psnr))
            row["novel_view_spp"] = spp
            log.info("snapshot %s: novel views at %d spp in %.2f s", path.name, spp, time.perf_counter() - t0)
        table.append(row)
    return table
