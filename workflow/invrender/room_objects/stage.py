"""The `room_objects` stage (mode `room`, PSDR-Room section 4.3): every object of one photo
retrieved from the asset library, placed coarsely from its points, on its support, then all
refined jointly by Eq. 3 through differentiable rendering; after the room_box stage.

    out_dir/objects.json      {"objects": [{"segment", "name", "class", "asset", "category",
                               "position", "yaw_deg", "scale", "size", "support", "candidates",
                               "coarse", "mask_iou"}], "skipped", "box", "camera", "losses",
                               "metrics", "units", "depth_scale", "inputs", "settings", "seconds"}
    out_dir/room_objects.png  the photo twice, each object's silhouette outline and asset name:
                               coarse (left), refined (right)

Placements are the room generator's (truth/room.json's): world = R_y(yaw) (scale * unit mesh) +
position, ``position`` the footprint's centre at its support's height, ``scale`` the largest
extent; in room.json's world and units (room_box's). Docs: docs/room-objects.md.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .. import assets
from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import binned_camera
from ..scene.images import linear_to_srgb
from ..scene.room_photo import load_room_photo
from ..scene.room_scene import read_json, room_camera
from ..scene.types import Camera, SceneError, require_positive
from . import metrics as measures
from .placement import (
    FLOOR,
    CoarseSettings,
    Placement,
    Segment,
    coarse_placement,
    segment_points,
    support_order,
    supports,
)
from .refine import RefineSettings, block_factor, exact_losses, reduced_targets, refine

__all__ = ["run", "read_room", "Settings"]

logger = logging.getLogger(__name__)

KIND = "room_objects"
OBJECT_CLASSES = ("object", "lamp")
RANK_MARGIN = 0.05  # Eq. 3 loss a candidate gives away per rank of retrieval (stage._choose)
METRIC_WIDTH = 512  # the exact masks' width for the IoU (block-reduced photo segments)


@dataclass
class Settings:
    candidates: int = 3  # top-k assets per object, each refined; the lowest refined loss is kept
    asset_dirs: tuple = ()  # user folders of OBJ/PLY/USD models, besides the bundled furniture
    min_pixels: int = 64  # smaller segments are skipped (retrieval needs a silhouette)
    coarse: CoarseSettings = field(default_factory=CoarseSettings)
    refine: RefineSettings = field(default_factory=RefineSettings)


def read_room(room_json) -> dict:
    """room_box's room.json: the box, the camera (scene/room_scene.room_camera) and depth_scale,
    with one SceneError naming what is wrong."""
    room_json = Path(room_json)
    doc = read_json(room_json, "the room_box stage's room.json")
    camera = room_camera(doc, room_json)
    try:
        b = doc["box"]
        room = {
            "box": (
                np.asarray(b["center"], float).reshape(3),
                np.asarray(b["size"], float).reshape(3),
                float(b.get("yaw_deg", 0.0)),
            ),
            "camera": camera,
            "depth_scale": float(doc["depth_scale"]),
            "truth_scale": float(doc.get("metrics", {}).get("truth_scale", 1.0)),
            "json": {"box": b, "camera": doc["camera"]},
        }
    except (ValueError, KeyError, TypeError) as error:
        raise SceneError(
            room_json, "box/depth_scale", f"room_box's box {{center, size, yaw_deg}} and depth_scale ({error})"
        ) from None
    if np.any(room["box"][1] <= 0) or not room["depth_scale"] > 0:
        raise SceneError(room_json, "box.size/depth_scale", "positive sizes and a positive depth_scale")
    return room


def _normalised(camera: Camera, scale: float) -> Camera:
    return Camera(camera.name, camera.model, camera.width, camera.height, camera.params, camera.R, camera.t / scale)


def _segments(photo, depth, camera, box, settings: Settings, log) -> tuple[list[Segment], list[dict]]:
    """The photo's object and lamp segments with their points (normalised units); the skipped ones
    with the reason: too small, no depth, or a lamp on the ceiling (a light of the room: room_lights')."""
    found, skipped = [], []
    height = box[0][1] + box[1][1] / 2  # the ceiling
    for sid, (cls, name) in sorted(photo.labels.items()):
        if cls not in OBJECT_CLASSES:
            continue
        mask = photo.segments == sid
        reason = None
        if mask.sum() < settings.min_pixels:
            reason = f"{int(mask.sum())} pixels, fewer than min_pixels {settings.min_pixels}"
        else:
            points = segment_points(mask, depth, camera, settings.coarse.erosion)
            if len(points) < 3:
                reason = "no depth"
            elif cls == "lamp" and np.percentile(points[:, 1], 2) > height - settings.coarse.floor_distance:
                reason = "a lamp on the ceiling: a light of the room (room_lights' work)"
        if reason:
            skipped.append({"segment": int(sid), "name": name, "class": cls, "reason": reason})
            log.info("room_objects: segment %d (%s) skipped: %s", sid, name, reason)
            continue
        z = (points - camera.center) @ np.asarray(camera.R)[2]
        found.append(Segment(int(sid), cls, name, mask, points, z))
    return found, skipped


def _retrieve(segments, photo, camera, library, descriptors, k: int) -> None:
    up = np.asarray(camera.R)[:, 1]  # the world's +Y (the floor's normal) in the camera frame
    for seg in segments:
        seg.candidates = assets.retrieve(seg.mask, photo.depth, descriptors, k=k, focal=camera.focal[1], up=up)


def _coarse_round(segments, parents, rank, by_name, targets, settings) -> list[Placement]:
    """The coarse placements of every object's ``rank``-th candidate (its last when it has fewer), in
    support order: a child stands on its parent's coarse top."""
    placed = []
    occupied = targets.masks.sum(axis=0)
    for i, seg in enumerate(segments):
        match = seg.candidates[min(rank, len(seg.candidates) - 1)]
        if parents[i] is not None:
            height = placed[parents[i]].top
        else:
            height = 0.0 if seg.support == FLOOR else None
        ignore = (occupied - targets.masks[i]) > 0.5  # another object's pixels may hide this one
        target_depth = float(np.median(seg.depth))
        view_yaw = assets.yaw_from_view(match.azimuth_deg, seg.centre, targets.camera.center)
        place, _ = coarse_placement(
            seg,
            by_name[match.name],
            height,
            targets.camera,
            targets.masks[i],
            ignore,
            target_depth,
            settings.coarse,
            view_yaw,
        )
        placed.append(place)
    return placed


def run(
    capture_dir,
    room_dir,
    out_dir,
    settings: Settings | None = None,
    truth_dir=None,
    files: dict | None = None,
    seed: int = 0,
    device: str | None = None,
    render=None,
    log: logging.Logger = logger,
) -> dict:
    """Place the objects of the capture in ``capture_dir`` in the room of ``room_dir`` (room.json);
    write ``out_dir``; return objects.json's content. ``truth_dir``: default the capture's truth/
    when it has one. ``files``: load_room_photo's photo, depth, ids, labels where not the default names."""
    started = time.perf_counter()
    settings = settings or Settings()
    for name, value in (("candidates", settings.candidates), ("iterations", settings.refine.iterations),
                        ("spp", settings.refine.spp), ("max_width", settings.refine.max_width),
                        ("yaw_steps", settings.coarse.yaw_steps)):  # fmt: skip
        require_positive("room-objects", name.replace("_", "-"), value)
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    check_output(out_dir, KIND)
    room = read_room(Path(room_dir) / "room.json")
    photo = load_room_photo(capture_dir, **(files or {}), require=("depth", "segmentation"))
    if (photo.width, photo.height) != (room["camera"].width, room["camera"].height):
        raise SceneError(
            Path(room_dir) / "room.json", "camera",
            f"the photo's size {photo.width} x {photo.height}, got {room['camera'].width} x {room['camera'].height}",
        )  # fmt: skip
    scale = room["depth_scale"]
    depth = np.where(photo.depth > 0, photo.depth / scale, 0.0)
    camera = _normalised(room["camera"], scale)
    box = (room["box"][0] / scale, room["box"][1] / scale, room["box"][2])
    library = assets.library(tuple(settings.asset_dirs))
    by_name = {a.name: a for a in library}

    segments, skipped = _segments(photo, depth, camera, box, settings, log)
    if not segments:
        log.info("room_objects: the photo has no object segments to place: objects.json lists none")
    descriptors = assets.library_descriptors(library) if segments else None
    _retrieve(segments, photo, camera, library, descriptors, settings.candidates)
    supports(segments, photo.class_mask("floor"), settings.coarse)
    segments = support_order(segments)
    index = {str(s.id): i for i, s in enumerate(segments)}
    parents = [index.get(s.support) for s in segments]
    targets = reduced_targets([s.mask for s in segments], depth, camera, settings.refine.max_width)

    rounds, history = [], []
    k = max((len(s.candidates) for s in segments), default=0)
    for rank in range(k):
        coarse = _coarse_round(segments, parents, rank, by_name, targets, settings)
        refined, losses, steps = refine(
            coarse, [s.support for s in segments], parents, targets, box, settings.refine,
            seed=seed + 1000 * rank, render=render, device=device, log=log,
        )  # fmt: skip
        rounds.append((coarse, refined, losses))
        history.append(
            [{"step": h["step"], "loss": round(h["loss"], 6), "iou": [round(v, 4) for v in h["iou"]]} for h in steps]
        )
        log.info("room_objects: candidates of rank %d refined: losses %s", rank, np.round(losses, 4).tolist())
    final, exact = _choose(rounds, parents, targets, settings.refine)
    first = rounds[0][0] if rounds else []

    metric_camera, metric_masks = _metric_view(photo, segments, camera)
    report_metrics = {
        "coarse": {"mask_iou": measures.mask_ious(first, metric_masks, metric_camera)},
        "refined": {"mask_iou": measures.mask_ious(final, metric_masks, metric_camera)},
    }
    for which in ("coarse", "refined"):
        ious = [v for v in report_metrics[which]["mask_iou"] if v is not None]
        report_metrics[which]["mean_mask_iou"] = round(float(np.mean(ious)), 4) if ious else None
    truth_dir = Path(truth_dir) if truth_dir is not None else capture_dir / "truth"
    truth = measures.read_truth(truth_dir) if truth_dir.exists() else None
    if truth is not None:
        symmetry = {a.name: a.symmetry for a in library}
        shown = {int(i) for i in np.unique(photo.segments)}
        for which, places in (("coarse", first), ("refined", final)):
            by_segment = {s.id: p for s, p in zip(segments, places)}
            report_metrics[which].update(
                measures.truth_metrics(by_segment, camera, scale, truth, room["truth_scale"], symmetry, shown)
            )
        report_metrics["truth_scale"] = room["truth_scale"]

    objects = [
        _object_json(seg, first[i], final[i], [r[2][i] for r in rounds], exact[i], scale, report_metrics, i)
        for i, seg in enumerate(segments)
    ]
    report = {
        "objects": objects,
        "skipped": skipped,
        "box": room["json"]["box"],
        "camera": room["json"]["camera"],
        "losses": history,
        "metrics": report_metrics,
        "units": "room.json's (the depth's; meters for a metric depth)",
        "depth_scale": round(scale, 6),
        "truth": str(truth_dir) if truth is not None else None,
        "inputs": {"capture": str(capture_dir), "room": str(Path(room_dir) / "room.json")}
        | {name: str(path) for name, path in photo.paths.items()},
        "settings": _settings_json(settings) | {"seed": seed},
    }
    report["seconds"] = round(time.perf_counter() - started, 2)
    figure = objects_figure(photo.image, room["camera"], scale, first, final)
    with atomic_dir(out_dir, kind=KIND) as tmp:
        (Path(tmp) / "objects.json").write_text(json.dumps(report, indent=1, allow_nan=False) + "\n")
        cv2.imwrite(str(Path(tmp) / "room_objects.png"), figure)
    _log_metrics(log, report_metrics)
    log.info(
        "room_objects: %d objects (%d skipped) %s -> %s in %.1f s",
        len(objects),
        len(skipped),
        capture_dir,
        out_dir,
        report["seconds"],
    )
    return report


def _choose(rounds, parents, targets, settings: RefineSettings) -> tuple[list[Placement], list[list[float]]]:
    """Each object's candidate of the least exact Eq. 3 loss (refine.exact_losses) plus RANK_MARGIN
    times its retrieval rank, its refined placement tried among the others' current choices (the
    first rank's to begin with), objects in support order; then each child set on its parent's
    chosen top. Returns the placements and each object's exact loss per candidate."""
    current = [Placement(p.asset, p.position.copy(), p.yaw_deg, p.scale) for p in rounds[0][1]] if rounds else []
    exact = []
    for i in range(len(current)):
        tried = []
        for _, refined, _ in rounds:
            trial = current[:i] + [refined[i]] + current[i + 1 :]
            tried.append(float(exact_losses(trial, targets, settings)[i]))
        # A later rank must win by more than RANK_MARGIN a rank: near-ties (the bedroom's book box:
        # box_a 0.410, cabinet_a 0.399) are within the loss's resolution, and the retrieval's order decides.
        best = rounds[int(np.argmin(np.asarray(tried) + RANK_MARGIN * np.arange(len(tried))))][1][i]
        current[i] = Placement(best.asset, best.position.copy(), best.yaw_deg, best.scale)
        exact.append(tried)
    for i, j in enumerate(parents):  # a parent may have changed its asset: stand on its chosen top
        if j is not None:
            current[i].position[1] = current[j].top
    return current, exact


def _metric_view(photo, segments, camera) -> tuple[Camera, list[np.ndarray]]:
    """The camera and the segments' masks at most METRIC_WIDTH wide (a block's majority)."""
    factor = block_factor(photo.width, METRIC_WIDTH)
    small = binned_camera(camera, factor)
    h, w = small.height, small.width
    masks = [
        seg.mask[: h * factor, : w * factor].reshape(h, factor, w, factor).mean(axis=(1, 3)) > 0.5 for seg in segments
    ]
    return small, masks


def _place_json(place: Placement, scale: float) -> dict:
    return {
        "asset": place.asset.name,
        "category": place.asset.category,
        "position": [round(float(v) * scale, 6) for v in place.position],
        "yaw_deg": round(place.yaw_deg % 360.0, 4),
        "scale": round(place.scale * scale, 6),
        "size": [round(float(v) * place.scale * scale, 6) for v in place.asset.extent],
    }


def _object_json(seg: Segment, coarse: Placement, final: Placement, losses, exact, scale, report_metrics, i) -> dict:
    candidates = [
        {"asset": m.name, "category": m.category, "distance": round(m.distance, 6), "loss": round(float(loss), 6)}
        | {"exact_loss": round(float(e), 6)}
        for m, loss, e in zip(seg.candidates, losses, exact)
    ]
    return {
        "segment": seg.id,
        "name": seg.name,
        "class": seg.cls,
        **_place_json(final, scale),
        "support": seg.support,
        "candidates": candidates,
        "coarse": _place_json(coarse, scale),
        "mask_iou": {w: report_metrics[w]["mask_iou"][i] for w in ("coarse", "refined")},
    }


def _settings_json(settings: Settings) -> dict:
    out = asdict(settings)
    out["asset_dirs"] = [str(d) for d in settings.asset_dirs]
    return out


def _log_metrics(log, m: dict) -> None:
    for which in ("coarse", "refined"):
        r = m[which]
        extra = ""
        if "asset_accuracy" in r:
            extra = (
                f", asset {r['asset_accuracy']}, category {r['category_accuracy']}, position {r['position_error']} m, "
                f"yaw {r['yaw_error_deg']} deg, scale {r['scale_error']}"
            )
        log.info("room_objects: %s: mask IoU %s%s", which, r["mask_iou"], extra)


# ---------------------------------------------------------------------------- the figure

COLOURS = [
    (60, 220, 60),
    (255, 160, 40),
    (40, 200, 255),
    (230, 80, 230),
    (80, 80, 255),
    (255, 255, 80),
    (180, 120, 255),
]
PANEL_WIDTH = 640


def _bgr(image: np.ndarray) -> np.ndarray:
    level = float(np.percentile(image.max(axis=2), 99)) if image.size else 1.0
    rgb = linear_to_srgb(np.clip(image / (level if level > 0 else 1.0), 0, 1))
    return np.ascontiguousarray((rgb * 255 + 0.5).astype(np.uint8)[..., ::-1])


def _panel(photo: np.ndarray, placements: list[Placement], camera: Camera, caption: str) -> np.ndarray:
    from .placement import label_image

    labels, _ = label_image(placements, camera)
    panel = cv2.resize(photo, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    for i, place in enumerate(placements):
        mask = (labels == i).astype(np.uint8)
        if not mask.any():
            continue
        colour = COLOURS[i % len(COLOURS)]
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(panel, contours, -1, colour, 2, cv2.LINE_AA)
        ys, xs = np.nonzero(mask)
        at = (int(xs.min()), max(int(ys.min()) - 4, 12))
        for thickness, c in ((3, (0, 0, 0)), (1, colour)):
            cv2.putText(panel, place.asset.name, at, cv2.FONT_HERSHEY_SIMPLEX, 0.45, c, thickness, cv2.LINE_AA)
    for thickness, c in ((3, (0, 0, 0)), (1, (255, 255, 255))):
        cv2.putText(panel, caption, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, c, thickness, cv2.LINE_AA)
    return panel


def objects_figure(image, camera: Camera, scale: float, coarse, refined) -> np.ndarray:
    """The photo twice at PANEL_WIDTH wide: each object's visible silhouette outline (exact labels)
    and its asset's name, coarse (left) and refined (right)."""
    k = PANEL_WIDTH / camera.width
    fx, fy, cx, cy = np.asarray(camera.params, float) * k
    small = Camera(
        "figure",
        "PINHOLE",
        PANEL_WIDTH,
        max(1, round(camera.height * k)),
        np.array([fx, fy, cx, cy]),
        camera.R,
        camera.t / scale,
    )
    photo = _bgr(np.asarray(image)[:, :, :3])
    return np.hstack([
        _panel(photo, coarse, small, "coarse (retrieval's first)"),
        _panel(photo, refined, small, "refined (Eq. 3), chosen candidates"),
    ])  # fmt: skip
