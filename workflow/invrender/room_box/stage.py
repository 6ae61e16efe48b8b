"""The `room_box` stage (mode `room`, PSDR-Room section 4.2): the room as a box, from one photo's
depth, wall/floor/ceiling segmentation and field of view.

    out_dir/room.json    {"box": {"center", "size", "yaw_deg"} (as truth/room.json), "camera",
                          "floor", "coarse": {"box", ...}, "losses": [...], "metrics": {...},
                          "units", "depth_scale", "inputs", "settings", "seconds"}
    out_dir/room_box.png the photo with the coarse (orange) and refined (green) box edges; the
                          photo's labels, the coarse box's and the refined box's, side by side

The coarse box (coarse.py) and its refinement by Eq. 2 (refine.py) work on the depth divided by
its median (the paper's normalised depth); the box and camera are written in the depth's own
units (meters for a metric depth, such as the synthetic rooms'). The world written is the
refined box's: +Y up, the floor at y = 0, the box centred on x and z with yaw 0 (the room
generator's convention), the camera posed in it. Metrics (metrics.py) for both boxes: mask IoU
per class and depth error against the photo's labels and depth, and with a truth
(``truth_dir``/room.json and the scene's camera) the corner error in the truth's units.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np

from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import read_cameras
from ..scene.images import linear_to_srgb
from ..scene.room_photo import fov_x_to_y, load_room_photo
from ..scene.types import Camera, SceneError, require_positive
from .box import BOX_CLASSES, RoomBox, box_corners
from .coarse import CoarseSettings, fit_coarse_box
from .metrics import image_metrics, truth_metrics, truth_scale
from .refine import RefineSettings, reduced_targets, refine_box

__all__ = ["run", "photo_camera", "read_truth", "room_figure"]

logger = logging.getLogger(__name__)

KIND = "room_box"


def photo_camera(width: int, height: int, fov_y_deg: float) -> Camera:
    """The photo's pinhole (square pixels, centred principal point), at the origin looking +z."""
    f = 0.5 * height / np.tan(np.radians(fov_y_deg) / 2)
    params = np.array([f, f, width / 2, height / 2])
    return Camera("photo", "PINHOLE", int(width), int(height), params, np.eye(3), np.zeros(3))


def _scaled(box: RoomBox, scale: float) -> RoomBox:
    return RoomBox(box.center * scale, box.size * scale, box.yaw_deg)


def _scaled_camera(camera: Camera, scale: float) -> Camera:
    return Camera(camera.name, camera.model, camera.width, camera.height, camera.params, camera.R, camera.t * scale)


def camera_json(camera: Camera, fov_y_deg: float) -> dict:
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    return {
        "model": "PINHOLE",
        "width": camera.width,
        "height": camera.height,
        "fov_y_deg": round(float(fov_y_deg), 6),
        "params": [round(float(v), 6) for v in (fx, fy, cx, cy)],
        "R": [[round(float(v), 9) for v in row] for row in camera.R],  # world-to-camera, OpenCV axes
        "t": [round(float(v), 6) for v in camera.t],
        "center": [round(float(v), 6) for v in camera.center],
    }


def read_truth(truth_dir) -> tuple[RoomBox, Camera] | None:
    """The truth box and the photo's true camera, or None without a truth: truth/room.json's
    "box" and "camera" (the room_photo generator's: width, height, fov_y_deg, world-to-camera R
    and t), else the first camera of the truth scene (scene/ or cameras/ beside room.json)."""
    truth_dir = Path(truth_dir)
    room_json = truth_dir / "room.json"
    if not room_json.is_file():
        return None
    try:
        doc = json.loads(room_json.read_text())
        box = RoomBox.from_json(doc["box"])
    except (KeyError, TypeError, ValueError) as error:
        raise SceneError(room_json, "box", f"{{center: [x, y, z], size: [sx, sy, sz], yaw_deg}} ({error})") from None
    if "camera" in doc:
        try:
            cam = doc["camera"]
            posed = photo_camera(int(cam["width"]), int(cam["height"]), float(cam["fov_y_deg"]))
            posed.R, posed.t = np.array(cam["R"], np.float64).reshape(3, 3), np.array(cam["t"], np.float64).reshape(3)
        except (KeyError, TypeError, ValueError) as error:
            raise SceneError(room_json, "camera", f"width, height, fov_y_deg, R (3 x 3), t (3) ({error})") from None
        return box, posed
    for cameras in (truth_dir / "scene" / "cameras", truth_dir / "cameras"):
        if cameras.exists():
            return box, read_cameras(cameras)[0]
    raise SceneError(room_json, "camera", "the photo's true camera (or a scene/cameras or cameras/ beside it)")


def _fov_y(photo, fov_y_deg, fov_x_deg, focal_length) -> float | None:
    """The vertical field of view: the one given (at most one of the three), else the capture's."""
    given = [v for v in (fov_y_deg, fov_x_deg, focal_length) if v is not None]
    if len(given) > 1:
        raise SceneError("room-box", "field of view", "at most one of fov_y_deg, fov_x_deg, focal_length")
    if given and not (given[0] > 0 and (focal_length is not None or given[0] < 180)):
        raise SceneError("room-box", "field of view", f"degrees in (0, 180) or a positive focal length, got {given[0]}")
    if fov_x_deg is not None:
        return fov_x_to_y(fov_x_deg, photo.width, photo.height)
    if focal_length is not None:
        return float(np.degrees(2 * np.arctan(0.5 * photo.height / focal_length)))
    return fov_y_deg if fov_y_deg is not None else photo.fov_y_deg


def _classes(photo) -> np.ndarray:
    classes = np.full((photo.height, photo.width), -1, np.int64)
    for i, name in enumerate(BOX_CLASSES):
        classes[photo.class_mask(name)] = i
    return classes


def run(
    capture_dir,
    out_dir,
    truth_dir=None,
    fov_y_deg: float | None = None,
    fov_x_deg: float | None = None,
    focal_length: float | None = None,
    files: dict | None = None,
    coarse: CoarseSettings | None = None,
    refine: RefineSettings | None = None,
    seed: int = 0,
    render=None,
    log: logging.Logger = logger,
) -> dict:
    """Fit the room box of the capture in ``capture_dir`` (scene/room_photo.py's layout); write
    ``out_dir``; return room.json's content. ``truth_dir``: default the capture's truth/ when it
    has one. The field of view: ``fov_y_deg`` (vertical), ``fov_x_deg`` (horizontal) or
    ``focal_length`` (pixels), else camera.json's. ``files``: the capture's files where they are not
    its default names (load_room_photo's photo, depth, ids, labels; relative to the capture).
    ``render``: the differentiable renderer (render_masks_depth by default)."""
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    coarse, refine = coarse or CoarseSettings(), refine or RefineSettings()
    started = time.perf_counter()
    for name in ("iterations", "spp", "max_width"):
        require_positive("room-box", f"--{name.replace('_', '-')}", getattr(refine, name))
    check_output(out_dir, KIND)
    photo = load_room_photo(capture_dir, **(files or {}), require=("depth", "segmentation"))
    photo.fov_y_deg = _fov_y(photo, fov_y_deg, fov_x_deg, focal_length)
    photo.fov_y_deg, fov_source = photo.field_of_view()  # else from vanishing points, or a SceneError
    valid = photo.depth > 0
    if not valid.any():
        raise SceneError(photo.paths["depth"], "depth", "a positive depth at some pixels (0 means unknown)")
    scale = float(np.median(photo.depth[valid]))
    depth = photo.normalised_depth().astype(np.float64)
    classes = _classes(photo)
    camera = photo_camera(photo.width, photo.height, photo.fov_y_deg)
    files = {"depth": photo.paths["depth"], "segmentation": photo.paths["ids"]}

    fit = fit_coarse_box(depth, classes, camera, coarse, seed=seed, files=files)
    log.info(
        "room_box: coarse box %s (ceiling %s, %d wall lines) in %.1f s",
        fit.box.to_json(),
        "seen" if fit.ceiling_seen else "not seen: 1.2x the top point",
        len(fit.wall_lines),
        time.perf_counter() - started,
    )
    targets = reduced_targets(classes, depth, fit.camera, refine.max_width)
    refined, history = refine_box(fit.box, targets, refine, seed=seed, render=render, log=log)

    # Each estimate is a box and the camera posed in its world: the coarse one in the floor's
    # world, the refined one in its own (upright, centred); both in the depth's units.
    upright, upright_camera = refined.upright(fit.camera)
    coarse_box, coarse_camera = _scaled(fit.box, scale), _scaled_camera(fit.camera, scale)
    box, posed = _scaled(upright, scale), _scaled_camera(upright_camera, scale)
    metrics = {
        "coarse": image_metrics(coarse_box, coarse_camera, classes, photo.depth, scale),
        "refined": image_metrics(box, posed, classes, photo.depth, scale),
    }
    truth_dir = Path(truth_dir) if truth_dir is not None else capture_dir / "truth"
    truth = read_truth(truth_dir) if truth_dir.exists() else None
    if truth is not None:
        to_truth = truth_scale(classes, photo.depth, *truth)
        metrics["truth_scale"] = round(to_truth, 6)
        metrics["coarse"].update(truth_metrics(coarse_box, coarse_camera, *truth, scale=to_truth))
        metrics["refined"].update(truth_metrics(box, posed, *truth, scale=to_truth))
    normal = posed.R[:, 1]  # the world's +Y in the camera frame
    tilt = np.degrees(np.arccos(np.clip(normal @ coarse_camera.R[:, 1], -1.0, 1.0)))
    report = {
        "box": box.to_json(),
        "camera": camera_json(posed, photo.fov_y_deg) | {"fov_source": fov_source},
        "floor": {
            "world": "y = 0",
            "normal_camera": [round(float(v), 6) for v in normal],
            "offset_camera": round(float(-normal @ posed.t), 6),  # n . p + offset = 0: the camera's height
            "tilt_from_ransac_deg": round(float(tilt), 4),  # how far the refinement turned the floor
            "ransac": fit.floor,
        },
        "coarse": {
            "box": coarse_box.to_json(),
            "camera": camera_json(coarse_camera, photo.fov_y_deg),
            "ceiling_seen": fit.ceiling_seen,
            "wall_lines": fit.wall_lines,
        },
        "losses": [{k: (round(v, 6) if isinstance(v, float) else v) for k, v in h.items()} for h in history],
        "metrics": metrics,
        "units": "the depth's (meters for a metric depth)",
        "depth_scale": round(scale, 6),
        "truth": str(truth_dir) if truth is not None else None,
        "inputs": {name: str(path) for name, path in photo.paths.items()},
        "settings": {"coarse": asdict(coarse), "refine": asdict(refine), "seed": seed},
    }
    report["seconds"] = round(time.perf_counter() - started, 2)
    figure = room_figure(photo.image, classes, (coarse_box, coarse_camera), (box, posed))
    with atomic_dir(out_dir, kind=KIND) as tmp:
        (Path(tmp) / "room.json").write_text(json.dumps(report, indent=1, allow_nan=False) + "\n")
        cv2.imwrite(str(Path(tmp) / "room_box.png"), figure)
    _log_metrics(log, metrics)
    log.info("room_box: %s -> %s in %.1f s", capture_dir, out_dir, report["seconds"])
    return report


def _log_metrics(log, metrics: dict) -> None:
    for which in ("coarse", "refined"):
        m = metrics[which]
        log.info(
            "room_box: %s: mask IoU %s, depth error %s%s",
            which,
            m["mask_iou"],
            m["depth_error"],
            f", corner error {m['corner_error']} (visible {m['visible_corner_error']})" if "corner_error" in m else "",
        )


# ---------------------------------------------------------------------------- the figure

CLASS_COLOURS = np.array([[170, 130, 90], [60, 110, 180], [230, 230, 210]], np.uint8)  # BGR: wall, floor, ceiling
EDGES = [
    (a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1
]  # corners differing in one axis


def _draw_box(image: np.ndarray, box: RoomBox, camera: Camera, colour, scale: float) -> None:
    """The box's 12 edges, each cut at a near plane in front of the camera (an edge of the room
    around the camera passes behind it)."""
    corners = box_corners(box) @ np.asarray(camera.R).T + np.asarray(camera.t)
    near = 1e-3 * float(np.abs(corners).max())
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    for a, b in EDGES:
        p, q = corners[a], corners[b]
        if p[2] < near and q[2] < near:
            continue
        if p[2] < near or q[2] < near:
            s = (near - p[2]) / (q[2] - p[2])
            cut = p + s * (q - p)
            p, q = (cut, q) if p[2] < near else (p, cut)
        ends = [
            (int(round(scale * (fx * v[0] / v[2] + cx))), int(round(scale * (fy * v[1] / v[2] + cy)))) for v in (p, q)
        ]
        ok, e0, e1 = cv2.clipLine((0, 0, image.shape[1], image.shape[0]), *ends)
        if ok:
            cv2.line(image, e0, e1, colour, 2, cv2.LINE_AA)


def _srgb8(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB -> 8-bit sRGB with the 99th percentile white, as the capture's PNG preview
    (scene.images.write_png_preview; a stage may not import segment/'s copy)."""
    level = float(np.percentile(rgb.max(axis=2), 99)) if rgb.size else 0.0
    return np.round(linear_to_srgb(rgb / (level if level > 0 else 1.0)) * 255).astype(np.uint8)


def _label_image(classes: np.ndarray) -> np.ndarray:
    out = np.zeros((*classes.shape, 3), np.uint8)
    for i in range(len(BOX_CLASSES)):
        out[classes == i] = CLASS_COLOURS[i]
    return out


def room_figure(image, classes, coarse: tuple[RoomBox, Camera], refined: tuple[RoomBox, Camera]) -> np.ndarray:
    """2 x 2 panels, each about 640 pixels wide: the photo with the coarse (orange) and refined
    (green) box; the photo's labels; the coarse and refined boxes' labels, red where they differ
    from the photo's (black: pixels that do not show the room, in the photo's labels). Each box
    comes with the camera posed in its world."""
    from .box import cast_box

    scale = 640 / max(image.shape[1], 1)
    if scale >= 1:
        scale = float(int(scale))  # a whole factor: pixels stay square blocks

    def resize(a, nearest=True):
        size = (round(a.shape[1] * scale), round(a.shape[0] * scale))
        return cv2.resize(a, size, interpolation=cv2.INTER_NEAREST if nearest or scale > 1 else cv2.INTER_AREA)

    photo = resize(_srgb8(np.asarray(image)[:, :, :3])[:, :, ::-1].copy(), nearest=False)
    _draw_box(photo, *coarse, (0, 140, 255), scale)
    _draw_box(photo, *refined, (60, 220, 60), scale)
    panels = [photo, resize(_label_image(classes))]
    for box, camera in (coarse, refined):
        labels = np.where(classes >= 0, cast_box(box, camera)[0], -1)
        panel = _label_image(labels)
        panel[labels != classes] = (0, 0, 255)
        panels.append(resize(panel))
    captions = ["photo: coarse (orange), refined (green)", "photo labels", "coarse box (red: differs)", "refined box"]
    for panel, caption in zip(panels, captions):
        cv2.putText(panel, caption, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(panel, caption, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
    return np.vstack([np.hstack(panels[:2]), np.hstack(panels[2:])])
