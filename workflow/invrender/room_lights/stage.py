"""The `room_lights` stage (mode `room`, PSDR-Room section 4.4, "Light initialization"): the
initial area lights of the room box (lights.py) and their radiance from one unit-radiance render
(radiance.py), after the room_box stage.

    out_dir/lights.json       {"lights": [{"kind", "name", "center", "e1", "e2", "normal",
                               "radiance": [r, g, b]}], "lamps": [{"segment", "name",
                               "radiance"}], "culled", "radiance_scale", "fit", "box", "camera",
                               "settings", "seconds"}
    out_dir/room_lights.png   the photo with the lights' outlines (yellow ceiling, red behind
                               the camera, magenta walls, cyan windows); beside it, at the fit's
                               size, the photo and s times the unit render

Geometry is in room.json's world and units (the box's and camera's). The scale is fitted over
the wall, floor and ceiling pixels (all pixels without a segmentation) of the photo and the
render reduced to ``max_width``; every light gets that one grey radiance, as the paper's
"uniform light radiance" initialisation.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np

from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import resized_camera
from ..scene.images import linear_to_srgb
from ..scene.room_photo import load_room_photo
from ..scene.room_scene import read_json, room_camera
from ..scene.types import Camera, SceneError, require_positive
from .lights import LightSettings, initial_lights
from .radiance import light_scene, radiance_scale, unit_render

__all__ = ["run", "read_room"]

logger = logging.getLogger(__name__)

KIND = "room_lights"
ROOM_PIXELS = ("wall", "floor", "ceiling")
KIND_COLOURS = {"ceiling": (0, 220, 255), "camera": (0, 0, 255), "wall": (255, 0, 255), "window": (255, 255, 0)}


def read_room(room_json) -> tuple[SimpleNamespace, Camera]:
    """room.json's box (center, size, yaw_deg) and camera (scene/room_scene.room_camera)."""
    room_json = Path(room_json)
    doc = read_json(room_json, "the room_box stage's room.json")
    try:
        b = doc["box"]
        box = SimpleNamespace(
            center=np.asarray(b["center"], float).reshape(3),
            size=np.asarray(b["size"], float).reshape(3),
            yaw_deg=float(b.get("yaw_deg", 0.0)),
        )
    except (ValueError, KeyError, TypeError) as error:
        raise SceneError(room_json, "box", f"room_box's box {{center, size, yaw_deg}} ({error})") from None
    if np.any(box.size <= 0):
        raise SceneError(room_json, "box.size", f"three positive extents, got {box.size.tolist()}")
    return box, room_camera(doc, room_json)


def _room_mask(photo, size) -> np.ndarray:
    """The pixels (at ``size`` = (W, H)) wholly on wall, floor or ceiling; all without labels."""
    if photo.segments is None or not photo.labels:
        return np.ones(size[::-1], bool)
    mask = np.zeros((photo.height, photo.width), np.float32)
    for name in ROOM_PIXELS:
        mask[photo.class_mask(name)] = 1.0
    return cv2.resize(mask, size, interpolation=cv2.INTER_AREA) > 0.999


def run(
    capture_dir,
    room_dir,
    out_dir,
    settings: LightSettings | None = None,
    spp: int = 16,
    max_width: int = 96,
    seed: int = 0,
    files: dict | None = None,
    device: str | None = None,
    log: logging.Logger = logger,
) -> dict:
    """The initial lights of the capture in ``capture_dir`` with the room box of ``room_dir``
    (room.json); write ``out_dir``; return lights.json's content."""
    started = time.perf_counter()
    settings = settings or LightSettings()
    require_positive("room-lights", "--spp", spp)
    require_positive("room-lights", "--max-width", max_width)
    if not settings.cell > 0:
        raise SceneError("room-lights", "cell", f"a positive fraction of the box, got {settings.cell}")
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    check_output(out_dir, KIND)
    box, camera = read_room(Path(room_dir) / "room.json")
    photo = load_room_photo(capture_dir, **(files or {}))
    if (photo.width, photo.height) != (camera.width, camera.height):
        raise SceneError(
            Path(room_dir) / "room.json",
            "camera",
            f"the photo's size {photo.width} x {photo.height}, got {camera.width} x {camera.height}",
        )
    lights = initial_lights(box, camera, settings, photo.segments, photo.labels)
    small = resized_camera(camera, min(camera.width, max_width))  # at most max_width wide
    scene = light_scene(box, lights.lights, small, inset=settings.inset)
    unit = unit_render(scene, small, spp=spp, seed=seed, device=device)
    target = cv2.resize(photo.image, (small.width, small.height), interpolation=cv2.INTER_AREA)
    mask = _room_mask(photo, (small.width, small.height))
    scale = radiance_scale(unit["radiance"], target, mask, variance=unit["variance"])
    residual = scale * unit["radiance"][mask] - target[mask]
    fit = {
        "pixels": int(mask.sum()),
        "rmse": round(float(np.sqrt(np.mean(residual**2))), 6),
        "photo_mean": round(float(target[mask].mean()), 6),
        "render_size": [small.width, small.height],
        "spp": spp,
    }
    radiance = [round(scale, 6)] * 3
    report = lights.to_json()
    for light in report["lights"]:
        light["radiance"] = radiance
    for lamp in report["lamps"]:
        lamp["radiance"] = radiance
    report |= {
        "radiance_scale": round(scale, 6),
        "fit": fit,
        "box": {"center": box.center.tolist(), "size": box.size.tolist(), "yaw_deg": box.yaw_deg},
        "inputs": {"capture": str(capture_dir), "room": str(Path(room_dir) / "room.json")},
        "settings": asdict(settings) | {"spp": spp, "max_width": max_width, "seed": seed},
    }
    report["seconds"] = round(time.perf_counter() - started, 2)
    figure = lights_figure(photo.image, camera, lights.lights, target, scale * unit["radiance"])
    with atomic_dir(out_dir, kind=KIND) as tmp:
        (Path(tmp) / "lights.json").write_text(json.dumps(report, indent=1, allow_nan=False) + "\n")
        cv2.imwrite(str(Path(tmp) / "room_lights.png"), figure)
    log.info(
        "room_lights: %d lights (%d ceiling cells culled in the frustum, %d behind the camera), %d lamps, "
        "radiance %.4g (rmse %.4g over %d pixels) in %.1f s",
        len(lights.lights),
        lights.culled["in_frustum"],
        lights.culled["behind_camera"],
        len(lights.lamps),
        scale,
        fit["rmse"],
        fit["pixels"],
        report["seconds"],
    )
    return report


def _bgr(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray((linear_to_srgb(np.clip(image, 0, 1)) * 255 + 0.5).astype(np.uint8)[..., ::-1])


def _outline(image: np.ndarray, quad, camera: Camera, colour) -> None:
    """The quad's edges, each cut at a near plane in front of the camera."""
    corners = quad.corners() @ np.asarray(camera.R).T + np.asarray(camera.t)
    near = 1e-3 * float(np.abs(corners).max())
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    for a in range(4):
        p, q = corners[a], corners[(a + 1) % 4]
        if p[2] < near and q[2] < near:
            continue
        if p[2] < near or q[2] < near:
            cut = p + (near - p[2]) / (q[2] - p[2]) * (q - p)
            p, q = (cut, q) if p[2] < near else (p, cut)
        ends = [(int(round(fx * v[0] / v[2] + cx)), int(round(fy * v[1] / v[2] + cy))) for v in (p, q)]
        ends = [(max(-(10**6), min(10**6, x)), max(-(10**6), min(10**6, y))) for x, y in ends]
        cv2.line(image, ends[0], ends[1], colour, 2, cv2.LINE_AA)


def lights_figure(image, camera: Camera, lights, target, fitted) -> np.ndarray:
    """The photo with every light's outline (only those in view show), then the reduced photo
    and the fitted render at the photo's height."""
    left = _bgr(image)
    for quad in lights:
        _outline(left, quad, camera, KIND_COLOURS.get(quad.kind, (255, 255, 255)))
    h = left.shape[0]
    w = max(1, round(target.shape[1] * h / target.shape[0]))
    panels = [cv2.resize(_bgr(x), (w, h), interpolation=cv2.INTER_NEAREST) for x in (target, fitted)]
    return np.concatenate([left, *panels], axis=1)
