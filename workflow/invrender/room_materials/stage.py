"""The `room_materials` stage (mode `room`, PSDR-Room section 4.4, "Material initialization and
search" and "Full scene material and lighting optimization"): a material for every part of the
assembled room and a radiance for every light, fitted to the photo.

    out_dir/materials.json   {"materials": {set or part name: {"kd", "ks", "ka"} constants |
                              {"atlas": "maps/NAME.npz"}} (bake --room's format, bake/room.py),
                              "sets": {part: {"kind", "preset", "params", "transform",
                              "meters_per_unit", "mapping", "segments", "crops", "retrieval"}},
                              "lights": {name: {"kind", "radiance"}}, "crops": [...],
                              "losses": [...], "metrics": {...}, "settings", "inputs", "seconds"}
    out_dir/lights.json      room_lights' lights.json with the fitted radiances (bake --room
                              reads lights from there)
    out_dir/maps/NAME.npz    a procedural part's object set baked (kd ks ka ke kw)
    out_dir/thumbnails.png   each part's kd under its transform
    out_dir/room_materials.png  per crop pair: the photo crop, the render before Eq. 4, after

The scene comes from scene/room_scene.assemble_room (room_box's room.json, room_objects'
objects.json, room_lights' lights.json, grey materials); its parts and lights from its metadata
(model.from_room_scene).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from ..assets.library import library
from ..materials.retrieval import default_network
from ..render.renderer import pixel_requests
from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import resized_camera
from ..scene.room_photo import load_room_photo
from ..scene.room_scene import assemble_room, read_json
from ..scene.types import SceneError
from .crops import CropPair, crop_rectangles, user_pairs
from .figures import crops_figure, thumbnails
from .init import plain, retrieve_part, seen_radiance, shading_albedo, tied_parts
from .metrics import psnr, truth_metrics
from .model import RoomModel, crop_camera, from_room_scene
from .optimise import Eq4, Eq4Settings, Views, make_renderer

__all__ = ["MaterialSettings", "run"]

logger = logging.getLogger(__name__)

KIND = "room_materials"
SURFACE_CLASSES = ("wall", "floor", "ceiling", "object")  # what materials, not lights, explain


@dataclass
class MaterialSettings:
    downsample: int = 8  # Eq. 4's image term at 1/8 of the photo's size (the paper)
    min_width: int = 64  # ... but at least this wide
    crops_per_part: int = 2
    min_crop: int = 24  # pixels, the shorter side of an automatic crop at the photo's size
    crop_size: int = 48  # pixels, a crop's longer side when rendered
    init_spp: int = 32
    init_passes: int = 2
    retrieve: bool = True
    fit_steps: int = 40
    eval_width: int = 256  # the PSNR's render
    eval_spp: int = 64
    # A ceiling the photo does not show at all (no segment of its class) is white paint: its
    # albedo is not observable but through interreflections, which absorb every light the scene
    # lacks (an unseen wall left free went to 0.23/0.14/0.08 for 0.62/0.63/0.60). Typical
    # ceiling white reflects 0.8-0.9 of the light (the synthetic rooms' 0.85/0.85/0.83).
    unseen_ceiling: float = 0.8


def _photo_masks(photo, parts) -> list[np.ndarray]:
    return [np.isin(photo.segments, np.asarray(p.segments, np.int64)) for p in parts]


def _small_masks(masks, size) -> np.ndarray:
    """Full-size masks to the small camera: a pixel counts when it is wholly inside."""
    return np.stack([cv2.resize(m.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.999 for m in masks])


def run(
    capture_dir,
    room_dir,
    out_dir,
    objects_dir=None,
    lights_dir=None,
    settings: MaterialSettings | None = None,
    eq4: Eq4Settings | None = None,
    user_crops=(),
    truth_dir=None,
    files: dict | None = None,
    seed: int = 0,
    device: str | None = None,
    log: logging.Logger = logger,
) -> dict:
    started = time.perf_counter()
    settings, eq4 = settings or MaterialSettings(), eq4 or Eq4Settings()
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    check_output(out_dir, KIND)
    photo = load_room_photo(capture_dir, **(files or {}))
    photo.require("segmentation")
    room = read_json(Path(room_dir) / "room.json", "the room_box stage's room.json")
    objects, dirs = [], []
    if objects_dir is not None:
        doc = read_json(Path(objects_dir) / "objects.json", "the room_objects stage's objects.json")
        objects = doc["objects"] if isinstance(doc, dict) else doc
        dirs = list(doc.get("asset_dirs", [])) if isinstance(doc, dict) else []
    lights_doc = (
        read_json(Path(lights_dir) / "lights.json", "the room_lights stage's lights.json") if lights_dir else {}
    )
    assets = {a.name: a for a in library(dirs)}
    scene = assemble_room(
        room, objects, lights_doc, {}, assets, labels=photo.labels, where=str(Path(room_dir) / "room.json")
    )
    camera = scene.cameras[0]
    if (camera.width, camera.height) != (photo.width, photo.height):
        raise SceneError(Path(room_dir) / "room.json", "camera", f"the photo's size {photo.width} x {photo.height}")
    parts, lights = from_room_scene(scene, photo.labels, assets)
    if not lights:
        raise SceneError(
            Path(lights_dir or room_dir), "lights", "at least one light (the room_lights stage's lights.json)"
        )
    model = RoomModel(scene, parts, lights)
    radiance = np.stack([light.radiance for light in lights])
    log.info("room_materials: %d parts, %d lights", len(parts), len(lights))

    # Where each part is seen: the render's part ids at the photo's pixels, and the photo's segments.
    grey = [plain([0.5] * 3) for _ in parts]
    renderer = make_renderer(model, grey, radiance, device=device)
    aov = renderer.aovs([camera], pixel_requests(camera))
    rendered = model.part_ids(aov["triangle_id"].reshape(photo.height, photo.width))
    radiance = seen_radiance(
        photo.image, model.light_ids(aov["triangle_id"].reshape(photo.height, photo.width)), radiance, eq4.light_colour
    )
    depth = aov["depth"].reshape(photo.height, photo.width)
    photo_masks = _photo_masks(photo, parts)
    inter = [(rendered == i) & photo_masks[i] for i in range(len(parts))]

    pairs: list[CropPair] = []
    for i, part in enumerate(parts):
        for r in crop_rectangles(inter[i], settings.crops_per_part, settings.min_crop):
            pairs.append(CropPair(part.name, r, r))
    pairs += user_pairs(user_crops, [p.name for p in parts], (photo.width, photo.height))
    part_index = {p.name: i for i, p in enumerate(parts)}

    # Median colours C_i (Eq. 4): of the intersection, else of the whole segment, else grey.
    medians = np.full((len(parts), 3), 0.5)
    coloured = [False] * len(parts)
    for i in range(len(parts)):
        for m in (inter[i], photo_masks[i]):
            if m.sum() >= 4:
                medians[i], coloured[i] = np.median(photo.image[m], axis=0), True
                break

    width = min(photo.width, max(settings.min_width, round(photo.width / settings.downsample)))
    small = resized_camera(camera, width)
    size = (small.width, small.height)
    photo_small = cv2.resize(photo.image, size, interpolation=cv2.INTER_AREA)
    masks_small = _small_masks(inter, size)
    init_started = time.perf_counter()
    # A part without pixels at the small size follows the seen parts of its segments.
    ties = tied_parts(parts, masks_small, coloured)
    albedo, shading = shading_albedo(
        renderer,
        model,
        radiance,
        small,
        photo_small,
        masks_small,
        medians,
        ties,
        settings.init_spp,
        settings.init_passes,
        seed,
        _unseen_start(parts, coloured, settings.unseen_ceiling),
    )
    materials = [plain(a) for a in albedo]

    # Procedural retrieval from each part's crops (the paper: a part with a crop pair).
    retrieval = {}
    net = default_network() if settings.retrieve else None
    fx = float(camera.focal[0])
    for i, part in enumerate(parts):
        own = [p for p in pairs if p.part == part.name]
        if not settings.retrieve or not own:
            continue
        crops = [p.photo.cut(photo.image) for p in own]
        largest = max(own, key=lambda p: p.photo.area)
        z = largest.render.cut(depth)
        z = float(np.median(z[z > 0])) if (z > 0).any() else 1.0
        mat, ranking, transform = retrieve_part(crops, albedo[i], largest.render.w * z / fx, settings.fit_steps, net)
        plain_distance = ranking.get("plain_grey")
        retrieval[part.name] = {"plain_distance": None if plain_distance is None else round(plain_distance, 6)} | {
            "ranking": {k: round(v, 6) for k, v in sorted(ranking.items(), key=lambda kv: kv[1])[:5]}
        }
        if mat is not None:
            materials[i] = mat
            retrieval[part.name]["chosen"] = mat.preset
        log.info("room_materials: %s: %s", part.name, retrieval[part.name].get("chosen", "plain"))
    init_seconds = time.perf_counter() - init_started

    # Eq. 4: the crops of procedural parts take the Gram term (a plain part's crop shows only
    # the render's noise to it).
    gram_pairs = [p for p in pairs if materials[part_index[p.part]].kind != "plain"]
    crop_cams = [crop_camera(camera, p.render, settings.crop_size, f"crop{k}") for k, p in enumerate(gram_pairs)]
    targets = [photo_small] + [
        cv2.resize(p.photo.cut(photo.image), (c.width, c.height), interpolation=cv2.INTER_AREA)
        for p, c in zip(gram_pairs, crop_cams)
    ]
    optimiser = Eq4(
        model,
        materials,
        radiance,
        renderer,
        Views(small, crop_cams),
        targets,
        masks_small,
        medians,
        [part_index[p.part] for p in gram_pairs],
        eq4,
        seed,
        ties=ties,
    )
    figure_cams = [crop_camera(camera, p.render, settings.crop_size, f"fig{k}") for k, p in enumerate(pairs)]
    eval_cam = resized_camera(camera, min(photo.width, settings.eval_width))
    eval_photo = cv2.resize(photo.image, (eval_cam.width, eval_cam.height), interpolation=cv2.INTER_AREA)

    def evaluate():
        optimiser.sync()
        views = Views(eval_cam, figure_cams)
        renderer.set_maps(model.maps(optimiser.materials, optimiser.radiance))
        mean, _, _ = renderer.render_requests(views.cameras, views.requests, settings.eval_spp, seed + 99)
        images = views.images(mean)
        return images[0], images[1:]

    before_image, before_crops = evaluate()
    eq4_started = time.perf_counter()
    history = optimiser.run()
    eq4_seconds = time.perf_counter() - eq4_started
    after_image, after_crops = evaluate()

    # Also over the surfaces alone: a lamp or window segment the scene has no emitter for (the
    # truth's ceiling panels: room_lights marks lamps, their geometry is the object stage's)
    # is a pixel no material can match, and it decides the whole image's PSNR.
    surfaces = np.isin(photo.segments, [sid for sid, (cls, _) in photo.labels.items() if cls in SURFACE_CLASSES])
    surfaces = (
        cv2.resize(surfaces.astype(np.float32), (eval_cam.width, eval_cam.height), interpolation=cv2.INTER_AREA) > 0.999
    )
    metrics = {
        "psnr_before": round(psnr(before_image, eval_photo), 3),
        "psnr_after": round(psnr(after_image, eval_photo), 3),
        "psnr_surfaces_before": round(psnr(before_image[surfaces], eval_photo[surfaces]), 3),
        "psnr_surfaces_after": round(psnr(after_image[surfaces], eval_photo[surfaces]), 3),
        "psnr_size": [eval_cam.width, eval_cam.height],
    }
    truth_dir = Path(truth_dir) if truth_dir is not None else capture_dir / "truth"
    if (truth_dir / "room.json").exists():
        truth_scale = float(((room.get("metrics") or {}).get("refined") or {}).get("truth_scale") or 1.0)
        metrics["truth"] = truth_metrics(
            truth_dir, model, optimiser.materials, optimiser.radiance, renderer, eval_cam, parts, truth_scale
        )
        log.info("room_materials: vs the truth %s", json.dumps(metrics["truth"]["summary"]))
    log.info("room_materials: PSNR %.2f -> %.2f dB", metrics["psnr_before"], metrics["psnr_after"])

    # A set holding a procedural part is written whole as its baked atlas (bake --room takes a
    # set's atlas, or constants per part).
    atlas_sets = sorted({_set_of(p.name) for p, m in zip(parts, optimiser.materials) if m.kind != "plain"})
    report = _report(parts, lights, optimiser, pairs, retrieval, history, metrics, atlas_sets, radiance)
    report |= {
        "settings": asdict(settings) | {"eq4": asdict(eq4), "seed": seed},
        "inputs": {
            "capture": str(capture_dir),
            "room": str(Path(room_dir) / "room.json"),
            "objects": str(Path(objects_dir) / "objects.json") if objects_dir else None,
            "lights": str(Path(lights_dir) / "lights.json") if lights_dir else None,
        },
        "seconds": {
            "init": round(init_seconds, 2),
            "eq4": round(eq4_seconds, 2),
            "total": round(time.perf_counter() - started, 2),
        },
    }
    photo_crops = [p.photo.cut(photo.image) for p in pairs]
    with atomic_dir(out_dir, kind=KIND) as tmp:
        tmp = Path(tmp)
        (tmp / "maps").mkdir()
        if atlas_sets:
            cut = scene.packing.unpack_atlas(model.maps(optimiser.materials, optimiser.radiance))
            for name in atlas_sets:
                np.savez_compressed(
                    tmp / "maps" / f"{name}.npz", **{m: getattr(cut[name], m) for m in ("kd", "ks", "ka", "ke", "kw")}
                )
        (tmp / "materials.json").write_text(json.dumps(report, indent=1, allow_nan=False) + "\n")
        (tmp / "lights.json").write_text(
            json.dumps(_lights_json(lights_doc, lights, optimiser.radiance), indent=1) + "\n"
        )
        cv2.imwrite(str(tmp / "thumbnails.png"), thumbnails([p.name for p in parts], optimiser.materials))
        cv2.imwrite(str(tmp / "room_materials.png"), crops_figure(pairs, photo_crops, before_crops, after_crops))
    log.info("room_materials: wrote %s in %.1f s", out_dir, report["seconds"]["total"])
    return report


def _unseen_start(parts, coloured, ceiling: float) -> np.ndarray:
    """The albedo of the parts no photo pixel shows at all (init.tied_parts follows none): the
    box's ceiling white (MaterialSettings.unseen_ceiling), the rest grey."""
    start = np.full((len(parts), 3), 0.5)
    for i, part in enumerate(parts):
        if not coloured[i] and part.plane is not None and part.name == "ceiling":
            start[i] = ceiling
    return start


def _set_of(part_name: str) -> str:
    """The scene set a part belongs to: an object's part ``{object}.{part}`` is in the object's
    set; a box surface is a set of its own."""
    return part_name.split(".", 1)[0]


def _lights_json(doc: dict, lights, radiance) -> dict:
    """room_lights' lights.json with the fitted radiances: quads by their scene name, lamps by
    their object's name."""
    out = json.loads(json.dumps(doc)) if doc else {"lights": [], "lamps": []}
    fitted = {light.name: np.round(radiance[j], 6).tolist() for j, light in enumerate(lights)}
    from ..scene.room_scene import safe_name

    for q in out.get("lights", []):
        name = safe_name(f"light_{q.get('name') or q.get('kind', 'light')}")
        if name in fitted:
            q["radiance"] = fitted[name]
    for lamp in out.get("lamps", []):
        for name, value in fitted.items():
            if lamp.get("name") and name.startswith(safe_name(str(lamp["name"])) + "."):
                lamp["radiance"] = value
    return out


def _report(parts, lights, optimiser, pairs, retrieval, history, metrics, atlas_sets, seen) -> dict:
    materials = {name: {"atlas": f"maps/{name}.npz"} for name in atlas_sets}
    sets = {}
    for i, (part, mat) in enumerate(zip(parts, optimiser.materials)):
        desc = mat.to_json()
        p = desc["params"]
        if _set_of(part.name) not in atlas_sets:
            materials[part.name] = {"kd": p["colour"], "ks": p["specular"], "ka": round(p["roughness"] ** 2, 6)}
        sets[part.name] = desc | {
            "mapping": "plane" if part.plane is not None else "box",
            "segments": list(part.segments),
            "crops": sum(1 for c in pairs if c.part == part.name),
            "retrieval": retrieval.get(part.name),
        }
    return {
        "materials": materials,
        "sets": sets,
        "lights": {
            light.name: {
                "kind": light.kind,
                "radiance": np.round(optimiser.radiance[j], 6).tolist(),
                "initial": np.round(light.radiance, 6).tolist(),
                "seen": np.round(seen[j], 6).tolist(),
            }
            for j, light in enumerate(lights)
        },
        "crops": [c.to_json() for c in pairs],
        "losses": history,
        "metrics": metrics,
    }
