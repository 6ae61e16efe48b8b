"""The `invrender` command: one subcommand per stage. It only parses arguments; each stage is a
function in the package that the tests call directly."""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import os
import signal
import sys
import tempfile
import threading
from dataclasses import fields
from pathlib import Path


def _key_values(pairs: list[str]) -> dict:
    """key=value pairs with JSON values (true, 3, 0.5), for feature overrides."""
    out = {}
    for pair in pairs or []:
        key, _, value = pair.partition("=")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError as error:
            raise SystemExit(f"--set {pair}: expected key=<JSON value>") from error
    return out


def _load_config(path: str | None) -> dict:
    if not path:
        return {}
    import yaml

    with open(path) as handle:
        return yaml.safe_load(handle) or {}


def cmd_synthesize(args):
    from .synthesize import stage

    stage.run(args.kind, Path(args.out), _load_config(args.config), spp=args.spp, seed=args.seed, device=args.device)


def cmd_features(args):
    from .features import stage
    from .render.analysis import AnalysisSettings

    analysis = _load_config(args.config).get("analysis", {})
    for field in fields(AnalysisSettings):  # flags win over the YAML
        if getattr(args, field.name) is not None:
            analysis[field.name] = getattr(args, field.name)
    stage.run(args.scene, args.out, AnalysisSettings(**analysis), _key_values(args.set), device=args.device)


def cmd_render(args):
    from .renders import stage

    stage.run(
        args.scene,
        args.out,
        args.features,
        spp=args.spp,
        seed=args.seed,
        cameras=args.camera,
        device=args.device,
        max_bounces=args.max_bounces,
        overrides=_key_values(args.set),
    )


def cmd_edit(args):
    from .edit import stage

    stage.run(
        args.scene,
        args.edits,
        args.out,
        truth_dir=args.truth,
        spp=args.spp,
        seed=args.seed,
        device=args.device,
        max_bounces=args.max_bounces,
    )


def cmd_cameras(args):
    from .cameras import stage

    if args.field_of_view is not None or args.focal_length is not None:
        stage.run_photograph(args.source, args.out, args.field_of_view, args.focal_length)
    else:
        stage.run(args.source, args.out, images_dir=args.images, face_size=args.face_size)


def cmd_geometry(args):
    from .geometry import stage
    from .scene.atomic import sweep_stale
    from .scene.isolate import call_isolated

    # pymeshlab's filters hold the GIL (Poisson, decimation: seconds to minutes), so SIGTERM would
    # wait for them: the stage runs in a child process that a signal here kills at once; the
    # temporary output that the killed child leaves is swept right away.
    try:
        call_isolated(
            stage.run,
            args.source,
            args.out,
            target_faces=args.target_faces,
            texels_per_meter=args.texels_per_meter,
            atlas_resolution=args.atlas_resolution,
            padding=args.padding,
            poisson_depth=args.poisson_depth,
            min_island_fraction=args.min_island_fraction,
            min_island_faces=args.min_island_faces,
            threads=args.threads,
            what="geometry",
        )
    finally:
        sweep_stale(args.out)


def cmd_segment(args):
    from .segment import stage

    stage.run(
        args.image,
        args.out,
        backend=args.backend,
        masks=args.masks,
        table=args.table,
        exemplar=args.exemplar,
        min_instances=args.min_instances,
        settings=_key_values(args.set),
    )


def cmd_room_box(args):
    from .room_box import stage
    from .room_box.coarse import CoarseSettings
    from .room_box.refine import RefineSettings

    stage.run(
        args.capture,
        args.out,
        truth_dir=args.truth,
        fov_y_deg=args.fov_y,
        fov_x_deg=args.fov_x,
        focal_length=args.focal_length,
        files={name: getattr(args, name) for name in ("photo", "depth", "ids", "labels") if getattr(args, name)},
        coarse=CoarseSettings.from_overrides(_key_values(args.coarse)),
        refine=RefineSettings(iterations=args.iterations, spp=args.spp, max_width=args.max_width),
        seed=args.seed,
    )


def cmd_room_lights(args):
    from .room_lights import stage
    from .room_lights.lights import LightSettings

    stage.run(
        args.capture,
        args.room,
        args.out,
        settings=LightSettings(cell=args.cell),
        spp=args.spp,
        max_width=args.max_width,
        seed=args.seed,
        files={name: getattr(args, name) for name in ("photo", "ids", "labels") if getattr(args, name)},
        device=args.device,
    )


def cmd_room_objects(args):
    from .room_objects import stage
    from .room_objects.refine import RefineSettings

    stage.run(
        args.capture,
        args.room,
        args.out,
        settings=stage.Settings(
            candidates=args.candidates,
            asset_dirs=tuple(args.asset_dir or ()),
            refine=RefineSettings(iterations=args.iterations, spp=args.spp, max_width=args.max_width),
        ),
        truth_dir=args.truth,
        files={name: getattr(args, name) for name in ("photo", "depth", "ids", "labels") if getattr(args, name)},
        seed=args.seed,
        device=args.device,
    )


def cmd_room_materials(args):
    from .room_materials import stage
    from .room_materials.optimise import Eq4Settings
    from .scene.types import SceneError

    crops = []
    if args.crops:
        text = args.crops
        try:
            if not text.lstrip().startswith("["):
                with open(text) as f:
                    text = f.read()
            crops = json.loads(text)
        except (OSError, json.JSONDecodeError) as error:
            raise SceneError(
                args.crops, "--crops", f"a JSON list of crop pairs, or a file holding one ({error})"
            ) from None
    stage.run(
        args.capture,
        args.room,
        args.out,
        objects_dir=args.objects,
        lights_dir=args.lights,
        settings=stage.MaterialSettings(retrieve=not args.no_retrieval, eval_width=args.eval_width),
        eq4=Eq4Settings(rounds=args.rounds, steps=args.steps, spp=args.spp, light_colour=args.light_colour),
        user_crops=crops,
        truth_dir=args.truth,
        files={name: getattr(args, name) for name in ("photo", "ids", "labels") if getattr(args, name)},
        seed=args.seed,
        device=args.device,
    )


def cmd_gradients(args):
    from .gradients import stage

    stage.run(
        args.geometry,
        args.cameras,
        args.images,
        args.out,
        batch=args.batch,
        spp=args.spp,
        seed=args.seed,
        iteration=args.iteration,
        device=args.device,
        accumulation=args.accumulation,
    )


def cmd_milo(args):
    from .milo import stage

    stage.run(
        args.geometry,
        args.cameras,
        args.images,
        args.out,
        preset=args.preset,
        overrides=_key_values(args.set),
        resume=args.resume,
        device=args.device,
    )


def _training_options(p, preset: str, presets: str) -> None:
    """A training stage's --preset, --set, --resume and --device (milo, duplicates-material)."""
    p.add_argument("--preset", default=preset, help=presets)
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a preset setting (JSON value)")
    p.add_argument(
        "--resume",
        choices=["never", "always", "auto"],
        default="never",
        help="continue from the newest checkpoint in OUT/checkpoints: always (refuse a missing, corrupt or "
        "mismatched one), auto (else start afresh), never",
    )
    p.add_argument("--device")


def cmd_duplicates_material(args):
    from .duplicates_material import stage

    stage.run(
        args.geometry,
        args.poses,
        args.cameras,
        args.masks,
        args.out,
        preset=args.preset,
        overrides=_key_values(args.set),
        resume=args.resume,
        device=args.device,
    )


def cmd_bake(args):
    from .bake import duplicates, room, stage

    if args.room:
        room.run(
            args.room,
            args.out,
            lights_dir=args.lights,
            objects_dir=args.objects,
            materials_dir=args.materials,
            capture_dir=args.capture,
            asset_dirs=args.assets,
            texels_per_meter=args.texels_per_meter,
            capture_files={name: getattr(args, name) for name in ("photo", "ids", "labels") if getattr(args, name)},
        )
        return
    for flag in ("geometry", "cameras"):
        if not getattr(args, flag):
            raise SystemExit(f"bake: --{flag} is required with --maps or --poses")
    if args.poses:
        if not args.masks and not args.material:
            raise SystemExit("bake --poses: --masks (the instance id PNG) or --material is required")
        duplicates.run(args.geometry, args.poses, args.cameras, args.masks, args.out, material_dir=args.material)
    else:
        stage.run(args.maps, args.geometry, args.cameras, args.out, training_path=args.training)


def cmd_export(args):
    from .export import stage

    stage.run(args.scene, args.out, usdc=args.usdc, poses=args.poses, instancing=not args.no_instancing)


def cmd_import(args):
    from .import_ import stage

    stage.run(
        args.source,
        args.out,
        cameras=args.cameras,
        environment=args.environment,
        cube_size=args.cube_size,
        emission_sides=args.emission_sides,
        windows=tuple(args.window or ()),
        max_atlas=args.max_atlas,
    )


def cmd_import_usd(args):
    from .export import import_usd

    import_usd(args.usd, args.out, exact=not args.standard_only)


def cmd_duplicates(args):
    from .duplicates import stage

    settings = stage.settings_from(_key_values(args.set))
    if args.step == "crop":
        stage.run_crop(args.cameras, args.masks, args.instance, args.crop, args.features, settings, image=args.image)
    else:
        stage.run(
            args.cameras, args.masks, args.instances, args.crops, args.features, args.out, settings, image=args.image
        )


def cmd_evaluate(args):
    from .evaluate import stage
    from .scene.types import SceneError

    if args.room:  # a room scene: the photo re-rendered, masks, box, objects, light, material
        from .evaluate import room

        for flag, value in (("--scene", args.scene), ("--capture", args.capture)):
            if not value:
                raise SceneError("evaluate --room", flag, "the room scene directory and its capture")
        room.run(
            args.scene,
            args.capture,
            args.room,
            args.out,
            objects_dir=args.objects,
            lights_dir=args.lights,
            truth_dir=args.truth,
            spp=args.spp,
            seed=args.seed,
            device=args.device,
        )
        return
    if not args.images:
        raise SceneError("evaluate", "--images", "the captured images (or --room for a room scene)")
    if args.duplicates:  # a duplicates scene: masks, poses and the shared mesh
        if not args.segmentation:
            raise SceneError("evaluate", "--segmentation", "the segment stage's folder beside --duplicates")
        stage.run_duplicates(
            args.segmentation,
            args.duplicates,
            args.truth,
            args.images,
            args.out,
            seed=args.seed,
            scene_dir=args.scene,
            training=args.training,
            spp=args.spp,
            device=args.device,
        )
        return
    for flag, value, what in (
        ("--scene", args.scene, "the recovered scene directory"),
        ("--atlas", args.atlas, "atlas.npz"),
    ):
        if not value:
            raise SceneError("evaluate", flag, f"{what} (or --duplicates for a duplicates scene)")
    stage.run(
        args.scene,
        args.truth,
        args.atlas,
        args.images,
        args.out,
        holdout=tuple(args.holdout or ()),
        snapshots_dir=args.snapshots,
        spp=args.spp,
        seed=args.seed,
        device=args.device,
        placement=_spheres(args.sphere),
    )


def _spheres(values) -> list[dict] | None:
    """--sphere KIND X Y Z RADIUS (repeatable) -> the stage's placement list (None: automatic)."""
    from .scene.types import SceneError

    if not values:
        return None
    spheres = []
    for kind, *numbers in values:
        try:
            x, y, z, radius = map(float, numbers)
        except ValueError:
            raise SceneError("evaluate --sphere", kind, f"four numbers X Y Z RADIUS, got {' '.join(numbers)}") from None
        spheres.append({"kind": kind, "center": [x, y, z], "radius": radius})
    return spheres


def cmd_accuracy(args):
    from .accuracy import stage
    from .accuracy.runs import read_run
    from .scene.types import SceneError

    runs = []
    if args.milo:  # the configured run: evaluate's scored snapshots if given, else its log
        runs.append(
            {"dir": args.milo, "metrics": args.metrics, "source": "milo", "label": "configured", "default": True}
        )
    for entry in args.run or []:  # SOURCE=DIR: another recovery stage's run (its log.csv, training.json)
        source, sep, directory = entry.partition("=")
        if not sep or not directory:
            raise SceneError(
                "accuracy --run", "run", f"SOURCE=DIR (e.g. duplicates_material=results/x/material), got {entry!r}"
            )
        metrics = args.metrics if not runs else None  # the configured run's score
        runs.append({"dir": directory, "metrics": metrics, "source": source, "label": source, "default": not runs})
    runs += [read_run(directory) for directory in args.sweep or []]
    stage.run(
        args.scene,
        args.features,
        args.out,
        images_dir=args.images,
        runs=runs,
        budget=args.budget,
        default_spp=args.default_spp,
        gradient_spp=args.gradient_spp,
        camera=args.camera,
        seed=args.seed,
        device=args.device,
    )


def cmd_assets(args):
    from .assets.tool import run

    run(args.what, args.out, args.user, args.shots, args.seed)


def cmd_accuracy_run(args):
    from .accuracy import runs
    from .scene.types import SceneError

    inputs = {}
    for entry in args.input or []:
        name, sep, path = entry.partition("=")
        if not sep or not path:
            raise SceneError(
                "accuracy-run --input", "input", f"NAME=PATH (e.g. geometry=results/x/geometry), got {entry!r}"
            )
        inputs[name] = path
    runs.train_and_score(
        args.out,
        args.source,
        inputs,
        args.preset,
        _key_values(args.set),
        label=args.label,
        spp=args.spp,
        seed=args.seed,
        device=args.device,
    )


def cmd_summary(args):
    from .accuracy import summary

    summary.run(args.results, args.out)


def cmd_devices(args):
    from .bench import devices

    devices.run(args.device, measure=not args.no_throughput)


def cmd_bench(args):
    from .bench import run_benchmark

    run_benchmark(args.what, args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="invrender", description=__doc__)
    parser.add_argument("--log", help="also write the log to this file")
    parser.add_argument("-v", "--verbose", action="store_true")
    stages = parser.add_subparsers(dest="stage", required=True, metavar="STAGE")

    p = stages.add_parser("synthesize", help="a parametric scene and its capture (the demo's input)")
    p.add_argument("kind", choices=["room", "duplicates", "room_photo"])
    p.add_argument("--out", required=True, help="capture directory to write")
    p.add_argument("--config", help="YAML with the scene's size, counts, resolutions")
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--seed", type=int, help="overrides the config's seed (scene and noise)")
    p.add_argument(
        "--device",
        help="OpenCL device name substring (default: the choice `invrender devices` shows)",
    )
    p.set_defaults(func=cmd_synthesize)

    p = stages.add_parser("features", help="decide which effects a scene calls for -> features.json")
    p.add_argument("scene", help="scene directory (scene.json)")
    p.add_argument("--out", required=True)
    p.add_argument("--config", help="YAML with an `analysis:` block (the flags below win over it)")
    p.add_argument("--bounce-fraction", type=float, help="power allowed beyond the last bounce (default 0.01)")
    p.add_argument("--specular-threshold", type=float, help="ks at or below which the lobe is compiled out")
    p.add_argument("--max-bounces", type=int, help="upper limit of the bounce count (default 10)")
    p.add_argument("--min-bounces", type=int, help="lower limit of the bounce count (default 1)")
    p.add_argument(
        "--roulette-depth",
        type=int,
        help="Russian roulette from this vertex on, if paths are longer (default 3; 0: off)",
    )
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a feature, e.g. specular=false")
    p.add_argument(
        "--device",
        help="OpenCL device for the escape probe (default: the choice `invrender devices` shows)",
    )
    p.set_defaults(func=cmd_features)

    p = stages.add_parser("render", help="render a scene's views (EXR + PNG preview + AOVs)")
    p.add_argument("scene")
    p.add_argument("--out", required=True)
    p.add_argument("--features", help="features.json (default: analyse the scene)")
    p.add_argument("--max-bounces", type=int, help="bounce limit (overrides the features' max_bounces)")
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a feature after analysis, e.g. specular=false (repeatable)",
    )
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--camera", action="append", help="render only this camera (repeatable)")
    p.add_argument("--device")
    p.set_defaults(func=cmd_render)

    p = stages.add_parser("edit", help="edit a scene (relight, insert, repaint, novel camera) and render it")
    p.add_argument("--scene", required=True, help="scene directory (scene.json)")
    p.add_argument("--edits", required=True, help="YAML or JSON list of edits (docs/edit.md)")
    p.add_argument("--out", required=True)
    p.add_argument("--truth", help="the true scene directory: the same edits rendered beside (<camera>_truth.exr)")
    p.add_argument("--max-bounces", type=int, help="bounce limit (overrides the analysis)")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device")
    p.set_defaults(func=cmd_edit)

    p = stages.add_parser(
        "cameras", help="a capture's cameras (COLMAP or transforms.json) and images -> a COLMAP text model + images/"
    )
    p.add_argument("source", help="COLMAP sparse model directory (text or binary) or transforms.json")
    p.add_argument("--out", required=True, help="directory to write the COLMAP text model (and images/) to")
    p.add_argument(
        "--images",
        help="the capture's images (COLMAP names are relative to it): checked and linked into OUT/images, "
        "equirectangular panoramas unwrapped into six cube faces each; without it, the model only",
    )
    p.add_argument("--face-size", type=int, help="cube-face width in pixels (default: a quarter of the panorama's)")
    lens = p.add_mutually_exclusive_group()
    lens.add_argument("--field-of-view", type=float, help="SOURCE is a photograph: its horizontal field of view (deg)")
    lens.add_argument("--focal-length", type=float, help="SOURCE is a photograph: its focal length in pixels")
    p.set_defaults(func=cmd_cameras)

    p = stages.add_parser(
        "geometry", help="clean/reconstruct, simplify, unwrap a mesh or point cloud -> mesh.ply, atlas.npz"
    )
    p.add_argument("source", help="PLY/OBJ triangle mesh, or PLY point cloud with normals (meters, +Y up)")
    p.add_argument("--out", required=True, help="directory to write (mesh.ply, atlas.npz, geometry.json)")
    p.add_argument("--target-faces", type=int, default=20000, help="quadric simplification target (MILO: 20K)")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--texels-per-meter", type=float, help="fixed texel density; the atlas grows to fit")
    size.add_argument("--atlas-resolution", type=int, default=1024, help="square atlas size in texels")
    p.add_argument("--padding", type=int, default=2, help="empty texels between charts")
    p.add_argument("--poisson-depth", type=int, default=8, help="screened Poisson octree depth (point clouds)")
    p.add_argument(
        "--min-island-fraction",
        type=float,
        default=0.01,
        help="remove pieces smaller than this fraction of the mesh's diagonal (lamps are larger)",
    )
    p.add_argument(
        "--min-island-faces", type=int, default=0, help="also remove pieces with fewer faces (0: size alone decides)"
    )
    p.add_argument("--threads", type=int, help="Poisson threads (default: the CPUs this process may use)")
    p.set_defaults(func=cmd_geometry)

    p = stages.add_parser(
        "segment", help="the copies of one object in one photograph -> masks/, instances.json, overlay.png"
    )
    p.add_argument("image", help="the photograph (EXR, PNG, JPEG)")
    p.add_argument("--out", required=True, help="directory to write (masks/, instances.json, overlay.png)")
    p.add_argument("--backend", choices=["opencv", "provided"], default="opencv")
    p.add_argument("--masks", help="provided: a PNG of instance ids (0 = background) or a folder of one PNG each")
    p.add_argument("--table", help="provided: JSON or CSV listing the ids the id image may hold")
    p.add_argument(
        "--exemplar", type=float, nargs=4, metavar=("X0", "Y0", "X1", "Y1"), help="opencv: a box around one copy"
    )
    p.add_argument("--min-instances", type=int, default=3, help="fewer stops the stage (at least 3)")
    p.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="opencv setting (OpenCVSettings in segment/opencv.py)"
    )
    p.set_defaults(func=cmd_segment)

    p = stages.add_parser("room-box", help="the room box of one photo (depth, segmentation, fov) -> room.json, figure")
    p.add_argument("capture", help="room capture directory (photo, depth.exr, panoptic.png/json, camera.json)")
    p.add_argument("--out", required=True, help="directory to write (room.json, room_box.png)")
    p.add_argument("--truth", help="truth directory (room.json, cameras/; default: the capture's truth/ if any)")
    lens = p.add_mutually_exclusive_group()
    lens.add_argument("--fov-y", type=float, help="vertical field of view in degrees (wins over camera.json)")
    lens.add_argument("--fov-x", type=float, help="horizontal field of view in degrees")
    lens.add_argument("--focal-length", type=float, help="focal length in pixels (square pixels, centred)")
    for name, what in (
        ("photo", "photograph"),
        ("depth", "depth EXR"),
        ("ids", "segment id PNG"),
        ("labels", "label table"),
    ):
        p.add_argument(f"--{name}", help=f"the {what}, relative to the capture (default: its standard name)")
    p.add_argument("--iterations", type=int, default=60, help="Adam steps of the refinement (Eq. 2)")
    p.add_argument("--spp", type=int, default=4, help="samples per pixel of each refinement render")
    p.add_argument("--max-width", type=int, default=128, help="width of the refinement's targets, at most")
    p.add_argument("--seed", type=int, default=0, help="RANSAC and render seed")
    p.add_argument(
        "--coarse",
        action="append",
        metavar="KEY=VALUE",
        help="coarse fit setting (CoarseSettings in room_box/coarse.py)",
    )
    p.set_defaults(func=cmd_room_box)

    p = stages.add_parser(
        "room-lights", help="the room's initial area lights and their radiance -> lights.json, figure"
    )
    p.add_argument("capture", help="room capture directory (photo, panoptic.png/json)")
    p.add_argument("--room", required=True, help="the room_box stage's output directory (room.json)")
    p.add_argument("--out", required=True, help="directory to write (lights.json, room_lights.png)")
    for name, what in (("photo", "photograph"), ("ids", "segment id PNG"), ("labels", "label table")):
        p.add_argument(f"--{name}", help=f"the {what}, relative to the capture (default: its standard name)")
    p.add_argument("--cell", type=float, default=0.25, help="ceiling grid cell, a fraction of the box's larger side")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of the unit-radiance render")
    p.add_argument("--max-width", type=int, default=96, help="width of the unit-radiance render, at most")
    p.add_argument("--seed", type=int, default=0, help="render seed")
    p.add_argument(
        "--device",
        help="OpenCL device for the unit-radiance render (default: the choice `invrender devices` shows)",
    )
    p.set_defaults(func=cmd_room_lights)

    p = stages.add_parser(
        "room-objects", help="the room's objects retrieved, placed and refined (Eq. 3) -> objects.json, figure"
    )
    p.add_argument("capture", help="room capture directory (photo, depth.exr, panoptic.png/json)")
    p.add_argument("--room", required=True, help="the room_box stage's output directory (room.json)")
    p.add_argument("--out", required=True, help="directory to write (objects.json, room_objects.png)")
    p.add_argument("--truth", help="truth directory (room.json; default: the capture's truth/ if any)")
    for name, what in (
        ("photo", "photograph"),
        ("depth", "depth EXR"),
        ("ids", "segment id PNG"),
        ("labels", "label table"),
    ):
        p.add_argument(f"--{name}", help=f"the {what}, relative to the capture (default: its standard name)")
    p.add_argument("--asset-dir", action="append", help="a folder of OBJ/PLY/USD models besides the bundled furniture")
    p.add_argument("--candidates", type=int, default=3, help="assets per object refined; the lowest loss is kept")
    p.add_argument("--iterations", type=int, default=40, help="Adam steps of the joint refinement (Eq. 3)")
    p.add_argument("--spp", type=int, default=4, help="samples per pixel of each refinement render")
    p.add_argument("--max-width", type=int, default=160, help="width of the refinement's targets, at most")
    p.add_argument("--seed", type=int, default=0, help="render seed")
    p.add_argument(
        "--device",
        help="OpenCL device for the refinement's renders (default: the choice `invrender devices` shows)",
    )
    p.set_defaults(func=cmd_room_objects)

    p = stages.add_parser(
        "room-materials", help="the room's materials and light radiances by Eq. 4 -> materials.json, figures"
    )
    p.add_argument("capture", help="room capture directory (photo, panoptic.png/json)")
    p.add_argument("--room", required=True, help="the room_box stage's output directory (room.json)")
    p.add_argument("--lights", required=True, help="the room_lights stage's output directory (lights.json)")
    p.add_argument("--objects", help="the room_objects stage's output directory (objects.json); none: an empty room")
    p.add_argument("--out", required=True, help="directory to write (materials.json, lights.json, figures)")
    for name, what in (("photo", "photograph"), ("ids", "segment id PNG"), ("labels", "label table")):
        p.add_argument(f"--{name}", help=f"the {what}, relative to the capture (default: its standard name)")
    p.add_argument("--crops", help="user crop pairs, JSON text or a file: [{part, photo: [x, y, w, h], render: [...]}]")
    p.add_argument("--truth", help="a synthetic room's truth directory (default: CAPTURE/truth when present)")
    p.add_argument("--rounds", type=int, default=4, help="Eq. 4 alternations (light solve, material steps)")
    p.add_argument("--steps", type=int, default=8, help="Adam steps on the materials per round")
    p.add_argument("--spp", type=int, default=8, help="samples per pixel of a material step")
    p.add_argument(
        "--light-colour", choices=("grey", "rgb"), default="grey", help="one radiance per light, or per channel"
    )
    p.add_argument("--no-retrieval", action="store_true", help="every part homogeneous (no procedural retrieval)")
    p.add_argument("--eval-width", type=int, default=256, help="width of the before/after render the PSNR is taken on")
    p.add_argument("--seed", type=int, default=0, help="render seed")
    p.add_argument("--device", help="OpenCL device (default: the choice `invrender devices` shows)")
    p.set_defaults(func=cmd_room_materials)

    p = stages.add_parser("gradients", help="d(image loss)/d(map) of the starting scene -> EXR + PNG per map")
    p.add_argument("--geometry", required=True, help="geometry stage output (mesh.ply with UVs, atlas.npz)")
    p.add_argument("--cameras", required=True, help="COLMAP model directory or transforms.json")
    p.add_argument("--images", required=True, help="directory of the captured images, named as the cameras' images")
    p.add_argument("--out", required=True)
    p.add_argument("--batch", type=int, default=65536, help="rays drawn from all pixels of all images (MILO: 65,536)")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--iteration", type=int, default=0, help="which batch of the seed's sequence")
    p.add_argument(
        "--accumulation",
        choices=["auto", "fixed", "buckets"],
        default="auto",
        help="fixed: 64-bit fixed point, bitwise reproducible; buckets: MILO's float copies; "
        "auto: fixed where the device has 64-bit integer atomics",
    )
    p.add_argument("--device")
    p.set_defaults(func=cmd_gradients)

    p = stages.add_parser("milo", help="train MILO-Net on a capture -> weights.pt, maps.npz, log.csv (rule milo_train)")
    p.add_argument("--geometry", required=True, help="geometry stage output (mesh.ply with UVs, atlas.npz)")
    p.add_argument("--cameras", required=True, help="COLMAP model directory or transforms.json")
    p.add_argument("--images", required=True, help="directory of the captured images, named as the cameras' images")
    p.add_argument("--out", required=True, help="directory to fill (weights.pt, maps.npz, log.csv, snapshots/, ...)")
    _training_options(p, "demo", "paper, cpu, demo or texels (docs/milo.md)")
    p.set_defaults(func=cmd_milo)

    p = stages.add_parser(
        "duplicates-material",
        help="the copies' shared material, the support's and the sky from the photograph(s) -> maps.npz, "
        "support/, log.csv (rule duplicates_material)",
    )
    p.add_argument("--geometry", required=True, help="geometry stage output (the shared mesh.ply, atlas.npz)")
    p.add_argument("--poses", required=True, help="poses.json of the duplicates stage")
    p.add_argument("--cameras", required=True, help="COLMAP model directory with images/")
    p.add_argument("--masks", required=True, help="the photograph's instance-id PNG, or a folder of <image stem>.png")
    p.add_argument("--out", required=True, help="directory to fill (maps.npz, support/, log.csv, snapshots/, ...)")
    _training_options(p, "ci", "ci or default (docs/duplicates-material.md)")
    p.set_defaults(func=cmd_duplicates_material)

    p = stages.add_parser("bake", help="recovered maps + mesh + cameras -> a scene directory")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--maps", help="maps.npz of the milo stage (a multiview scene)")
    source.add_argument("--poses", help="poses.json of the duplicates stage: the mesh instanced at every pose")
    source.add_argument("--room", help="room_box stage output (room.json): a room scene (docs/room.md, Bake)")
    p.add_argument("--geometry", help="geometry stage output (mesh.ply with UVs, atlas.npz); --maps, --poses")
    p.add_argument("--cameras", help="COLMAP model directory (with images/ for --poses); --maps, --poses")
    p.add_argument("--training", help="training.json of the milo stage (recorded in scene.json's metadata)")
    p.add_argument("--masks", help="with --poses: the instance id PNG (which copy each pixel shows)")
    p.add_argument(
        "--material", help="with --poses: the duplicates-material stage's folder (recovered atlas, sky, support)"
    )
    p.add_argument("--lights", help="with --room: room_lights stage output (lights.json)")
    p.add_argument("--objects", help="with --room: room_objects stage output (objects.json)")
    p.add_argument("--materials", help="with --room: room_materials stage output (materials.json)")
    p.add_argument("--capture", help="with --room: the room capture (panoptic.json names each object's class)")
    p.add_argument("--assets", action="append", default=[], help="with --room: a folder of user models (repeatable)")
    p.add_argument("--texels-per-meter", type=float, default=64.0, help="with --room: the atlases' texel density")
    p.add_argument("--ids", help="with --room: the capture's segment id PNG (relative to it)")
    p.add_argument("--labels", help="with --room: the capture's label table (relative to it)")
    p.add_argument("--photo", help="with --room: the capture's photo (relative to it)")
    p.add_argument("--out", required=True, help="scene directory to write")
    p.set_defaults(func=cmd_bake)

    p = stages.add_parser("export", help="a scene directory -> USD (scene.usda, textures/) for other tools")
    p.add_argument("scene", help="scene directory (scene.json)")
    p.add_argument("--out", required=True, help="directory to write (scene.usda, textures/, export.json)")
    p.add_argument("--usdc", action="store_true", help="also write scene.usdc (the same layer, binary)")
    p.add_argument("--poses", help="poses.json of duplicates (default: the poses in scene.json's metadata)")
    p.add_argument("--no-instancing", action="store_true", help="export duplicates as plain meshes")
    p.set_defaults(func=cmd_export)

    p = stages.add_parser("import", help="textured OBJ files + a lat-long environment + cameras -> a scene directory")
    p.add_argument("source", help="a folder of .obj files (with their mtllib and images), or one .obj")
    p.add_argument("--out", required=True, help="scene directory to write")
    p.add_argument(
        "--cameras", help="COLMAP model or transforms.json (default: SOURCE/sparse or SOURCE/transforms.json)"
    )
    p.add_argument("--environment", help="lat-long environment map (EXR or PNG, +Y up); default: black")
    p.add_argument("--cube-size", type=int, default=64, help="kg cube-map face size in texels")
    p.add_argument(
        "--emission-sides",
        choices=["one", "two"],
        default="one",
        help="emitters light their front only (as Mitsuba, Cycles, USD) or both sides",
    )
    p.add_argument(
        "--window",
        action="append",
        metavar="MATERIAL",
        help="a material that is an opening onto the environment (kw = 1); repeatable",
    )
    p.add_argument("--max-atlas", type=int, default=2048, help="largest atlas side of one material set")
    p.set_defaults(func=cmd_import)

    p = stages.add_parser("import-usd", help="a USD stage written by `export` (perhaps edited) -> a scene directory")
    p.add_argument("usd", help="scene.usda or scene.usdc")
    p.add_argument("--out", required=True, help="scene directory to write")
    p.add_argument(
        "--standard-only", action="store_true", help="ignore the invrender: attributes: the scene other USD tools see"
    )
    p.set_defaults(func=cmd_import_usd)

    p = stages.add_parser("duplicates", help="identical objects in one photo -> their poses and one shared mesh (SfD)")
    steps = p.add_subparsers(dest="step", required=True, metavar="STEP")
    for step, text in (
        ("crop", "one instance's crop and its features at every rotation angle"),
        ("solve", "match the crops, COLMAP's virtual cameras, hull, refinement -> poses.json, object.ply, sparse/"),
    ):
        q = steps.add_parser(step, help=text)
        q.add_argument("--cameras", required=True, help="the photograph's camera model with images/ (cameras stage)")
        q.add_argument("--image", help="the photograph's name, if the model has more than one camera")
        q.add_argument("--masks", required=True, help="instance id PNG (segment stage: masks/<image stem>.png)")
        q.add_argument("--features", required=True, help="crop: file to write; solve: folder of instance_NNN.npz")
        q.add_argument("--set", action="append", metavar="KEY=JSON", help="a setting (docs/duplicates.md), repeatable")
        q.set_defaults(func=cmd_duplicates)
        if step == "crop":
            q.add_argument("--instance", type=int, required=True, help="the instance id in the mask")
            q.add_argument("--crop", required=True, help="file to write (crop pixels, mask, offset, scale)")
        else:
            q.add_argument("--instances", required=True, help="segment stage's instances.json")
            q.add_argument("--crops", required=True, help="folder of instance_NNN.npz crops")
            q.add_argument("--out", required=True, help="directory to write")

    p = stages.add_parser("evaluate", help="a recovered scene against the truth -> metrics.json + figures")
    p.add_argument(
        "--scene", help="the recovered scene directory (multiview; with --duplicates: also score its appearance)"
    )
    p.add_argument(
        "--truth",
        required=True,
        help="the true scene directory (capture/ground_truth/scene); with --duplicates capture/ground_truth",
    )
    p.add_argument("--atlas", help="the recovered atlas' atlas.npz (geometry stage; multiview)")
    p.add_argument("--duplicates", help="a duplicates scene's duplicates/ folder (poses.json, object.ply)")
    p.add_argument("--segmentation", help="with --duplicates: the segment stage's folder (masks/, instances.json)")
    p.add_argument("--images", help="the captured images, named as the cameras' images (not with --room)")
    p.add_argument("--room", help="a room scene's room_box/ folder (room.json): --scene is the room scene")
    p.add_argument("--capture", help="with --room: the room capture (photo, panoptic segmentation)")
    p.add_argument("--objects", help="with --room: the room_objects folder (its metrics), if there")
    p.add_argument("--lights", help="with --room: the room_lights folder (its radiance fit), if there")
    p.add_argument("--out", required=True, help="directory to write (metrics.json, figures)")
    p.add_argument(
        "--holdout", nargs="+", action="extend", metavar="CAMERA", help="camera names held back from training"
    )
    p.add_argument("--snapshots", help="directory of training snapshots iter_XXXXXX.npz")
    p.add_argument(
        "--training", help="with --duplicates --scene: the material stage's training.json (time, memory), if it exists"
    )
    p.add_argument(
        "--sphere",
        nargs=5,
        action="append",
        metavar=("KIND", "X", "Y", "Z", "RADIUS"),
        help="an inserted sphere (diffuse, specular or emitting) in meters, repeatable (default: placed automatically)",
    )
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device")
    p.set_defaults(func=cmd_evaluate)

    p = stages.add_parser("accuracy", help="accuracy against time for every knob, the knee, the floors")
    p.add_argument("--scene", required=True, help="the scene directory the workflow renders")
    p.add_argument("--features", required=True, help="its features.json (the configured default)")
    p.add_argument("--out", required=True, help="directory to write (accuracy_vs_time.csv, accuracy.json, plots)")
    p.add_argument("--images", help="the captured images: the gradient sweep's loss (none: no gradient sweep)")
    p.add_argument("--milo", help="a MILO training directory (log.csv, training.json): the recovery rows")
    p.add_argument(
        "--metrics", help="evaluate's metrics.json of the configured run (--milo, else the first --run): its scores"
    )
    p.add_argument(
        "--run", action="append", metavar="SOURCE=DIR", help="another training run (log.csv, training.json), repeatable"
    )
    p.add_argument(
        "--sweep", action="append", metavar="DIR", help="a recovery run of `invrender accuracy-run`, repeatable"
    )
    p.add_argument("--budget", default="quick", help="quick (CI, seconds to a minute) or full (the README's figures)")
    p.add_argument("--default-spp", type=int, default=256, help="the configured render.spp (highlighted)")
    p.add_argument("--gradient-spp", type=int, default=16, help="the configured gradients.spp (highlighted)")
    p.add_argument("--camera", help="the camera swept (default: the scene's first)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device")
    p.set_defaults(func=cmd_accuracy)

    p = stages.add_parser(
        "assets", help="the asset library: its contact sheet, or retrieval's accuracy on it (docs/assets.md)"
    )
    p.add_argument("what", choices=["sheet", "accuracy"])
    p.add_argument("--out", help="sheet: the PNG to write (default assets.png); accuracy: a JSON of the numbers")
    p.add_argument(
        "--user", action="append", default=[], metavar="DIR", help="a folder of OBJ/PLY/USD models (repeatable)"
    )
    p.add_argument("--shots", type=int, default=5, help="accuracy: photo-like views of each asset")
    p.add_argument("--seed", type=int, default=0, help="accuracy: the shots' random seed")
    p.set_defaults(func=cmd_assets)

    p = stages.add_parser(
        "accuracy-run", help="one recovery configuration trained, baked and scored (rule recovery_run)"
    )
    p.add_argument("--source", required=True, help="the recovery stage: milo or duplicates_material")
    p.add_argument("--out", required=True, help="directory to write (run.json, train/, scene/, score/)")
    p.add_argument(
        "--input",
        action="append",
        metavar="NAME=PATH",
        help="the stage's inputs: milo geometry, cameras, images, truth (the truth scene); duplicates_material "
        "geometry, cameras, duplicates, masks, segmentation, truth (the capture's ground_truth), images",
    )
    p.add_argument("--preset", required=True, help="the stage's preset")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a preset setting (JSON value)")
    p.add_argument("--label", help="the run's name in the plots (default: the --out folder's name)")
    p.add_argument("--spp", type=int, default=4, help="evaluate's spp for the final scene's renders")
    p.add_argument("--seed", type=int, default=0, help="evaluate's seed")
    p.add_argument("--device")
    p.set_defaults(func=cmd_accuracy_run)

    p = stages.add_parser("summary", help="a scene's metrics beside the papers' and each rule's time and memory")
    p.add_argument("--results", required=True, help="the scene's results folder (results/{scene})")
    p.add_argument("--out", required=True, help="directory to write (runtime.html, runtime.png, metrics.html)")
    p.set_defaults(func=cmd_summary)

    p = stages.add_parser(
        "devices", help="every OpenCL device: does it build the kernels, how fast, which one a run uses and why"
    )
    p.add_argument("--device", help="what the config's `device:` would be (default: the automatic choice)")
    p.add_argument("--no-throughput", action="store_true", help="skip the short render on each device")
    p.set_defaults(func=cmd_devices)

    from .bench import BENCHMARKS

    p = stages.add_parser("bench", help="benchmarks (docs/benchmarks.md): against Mitsuba 3, MILO recovery")
    p.add_argument("what", choices=list(BENCHMARKS))
    p.add_argument("--quick", action="store_true", help="small sizes, to check the harness")
    p.add_argument("--out", default="docs/benchmarks", help="where the tables and plots go")
    p.add_argument("--device")
    milo = p.add_argument_group("bench milo")
    milo.add_argument("--config", help="the workflow config with the room (default config/benchmark.yaml)")
    milo.add_argument("--iterations", type=int, help="overrides the preset's iterations (quick runs)")
    milo.add_argument(
        "--ablation",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also train the plain-MLP ablation, template: false (default: yes)",
    )
    milo.add_argument(
        "--work", help="where the chain's stages write, kept to resume (default results/bench/milo, .../duplicates)"
    )
    dup = p.add_argument_group("bench duplicates")
    dup.add_argument(
        "--scenes", help="comma-separated duplicates presets (default the -hd boxes and cans); bench room: layouts"
    )
    dup.add_argument(
        "--variants",
        help="comma-separated bench duplicates variants (default provided-asift-refine, the ablation on "
        "box-10-hd); bench duplicates-material: the one whose poses are 'recovered' (default: default)",
    )
    dup.add_argument("--poses", help="bench duplicates-material: truth, recovered (default both; --quick truth)")
    summary = p.add_argument_group("bench summary")
    summary.add_argument(
        "--readme", help="the README whose results table to rewrite from --out's JSON files (default README.md)"
    )
    render = p.add_argument_group("bench render, bench milo")
    render.add_argument(
        "--sections",
        help="comma-separated sections to run (render: equal_rmse, bvh, features, profile; "
        "milo: independent, paper; default all)",
    )
    p.set_defaults(func=cmd_bench)
    return parser


class Terminated(SystemExit):
    """SIGTERM as an exception: exit status 128 + 15, after unwinding."""


def _exit_on_sigterm(signum, frame):
    # SIGTERM (scancel, a cluster's time limit, snakemake stopping its jobs) would end Python
    # without unwinding; as an exception it unwinds like Ctrl-C, so atomic outputs remove their
    # temporary files and nothing half-written is left beside the output.
    raise Terminated(128 + signum)


# Native modules whose import replaces the process's signal handlers without chaining to ours:
# pycolmap installs glog's failure handler, which on SIGTERM prints a stack and kills the process
# (no unwinding, so <out>.tmp-* stayed behind). Measured: pymeshlab, xatlas, OpenEXR, pyopencl,
# torch, pxr, cv2 do not; PoCL's device set-up installs handlers that call the previous ones.
# Importing these first, then installing ours, leaves ours in place: a later `import` of an
# already imported module does not run its initialisation again.
SIGNAL_TAKERS = ("pycolmap",)


def install_signal_handlers() -> None:
    for name in SIGNAL_TAKERS:
        try:
            importlib.import_module(name)
        except ImportError:
            pass
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    signal.signal(signal.SIGINT, signal.default_int_handler)


class _OneLine(logging.Formatter):
    """The terminal's lines: a traceback goes to the log file only (and here with -v)."""

    def format(self, record):
        if record.exc_info:
            record = logging.makeLogRecord(record.__dict__ | {"exc_info": None, "exc_text": None})
        return super().format(record)


def _os_error(error: OSError) -> str:
    """One line naming the file: "<path>: <what the system said>"."""
    names = [str(n) for n in (error.filename, error.filename2) if n is not None]
    return f"{' -> '.join(names) or '(no file named)'}: {error.strerror or error}"


def _log_handlers(args) -> list[logging.Handler]:
    stream = logging.StreamHandler(sys.stderr)
    stream.setFormatter((logging.Formatter if args.verbose else _OneLine)(FORMAT))
    handlers = [stream]
    if args.log:
        Path(args.log).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(args.log))  # flushes every record
        handlers[-1].setFormatter(logging.Formatter(FORMAT))
    return handlers


def _bug_log(args, handlers: list) -> str:
    """Where a bug's traceback goes: the --log file, else a file in the temporary directory."""
    if args.log:
        return args.log
    handle, path = tempfile.mkstemp(prefix=f"invrender-{args.stage}-", suffix=".log")
    os.close(handle)
    handlers.append(logging.FileHandler(path))
    handlers[-1].setFormatter(logging.Formatter(FORMAT))
    logging.getLogger("invrender").addHandler(handlers[-1])
    return path


FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"


def _is_device_error(error: Exception) -> bool:
    """No OpenCL device that can run the kernels is the machine's set-up, not a bug (exit 2). The
    class is looked up where it was raised, so verbs that trace no rays import no OpenCL."""
    device = sys.modules.get("invrender.render.device")
    return device is not None and isinstance(error, device.DeviceError)


def main(argv=None) -> int:
    """Run one stage. Exit status: 0 done; 2 bad input or an output that cannot be written (one
    line naming the file); 1 a bug (one line naming the log, the traceback in it); 130/143
    stopped by SIGINT/SIGTERM (nothing half-written is left). Every message also goes to --log."""
    args = build_parser().parse_args(argv)
    if threading.current_thread() is threading.main_thread():
        install_signal_handlers()
    # Handlers go on the package's logger, not the root: a host (pytest, a notebook) keeps its
    # own logging, and the rule's log file gets everything the stage says.
    log = logging.getLogger("invrender")
    log.setLevel(logging.DEBUG if args.verbose else logging.INFO)
    try:
        handlers = _log_handlers(args)
    except OSError as error:
        print(f"invrender: --log: {_os_error(error)}", file=sys.stderr)
        return 2
    for handler in handlers:
        log.addHandler(handler)
    from .scene.types import SceneError

    try:
        args.func(args)
    except SceneError as error:
        log.error("%s", error)
        return 2
    except OSError as error:  # permissions, a full disk, a parent that is a file
        log.error("%s", _os_error(error))
        return 2
    except KeyboardInterrupt:
        log.error("invrender %s: interrupted (SIGINT); no partial output left", args.stage)
        return 130
    except Terminated as stop:
        log.error("invrender %s: terminated (SIGTERM); no partial output left", args.stage)
        return stop.code
    except SystemExit as stop:  # an argument refused after parsing (--set): its message, logged too
        if not isinstance(stop.code, str):
            raise
        log.error("%s", stop.code)
        return 2
    except Exception as error:  # a bug: the user sees one line, the log has the traceback
        if _is_device_error(error):
            log.error("%s", error)
            return 2
        where = _bug_log(args, handlers)
        first = (str(error).splitlines() or [""])[0]  # one line: the rest is in the traceback
        log.error(
            "invrender %s failed: %s: %s (a bug; the traceback is in %s)",
            args.stage,
            type(error).__name__,
            first,
            where,
            exc_info=True,
        )
        return 1
    finally:
        for handler in handlers:
            log.removeHandler(handler)
            handler.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
