"""Synthetic room captures for the room_box tests: a box room (its truth known) cast exactly by
room_box.box.cast_box, an object standing in front of its back wall, optional depth noise, in
scene/room_photo.py's layout with a truth/ (room.json and the photo's camera)."""

from __future__ import annotations

import json

import numpy as np

from invrender.room_box.box import CEILING, FLOOR, WALL, RoomBox, cast_box, rotation_y
from invrender.scene.cameras import look_at
from invrender.scene.room_photo import write_room_photo
from invrender.scene.types import Camera

# Not centred, not axis-aligned: the fit must find the room's frame, not assume the generator's.
TRUTH = RoomBox([0.3, 1.35, -0.2], [4.2, 2.7, 3.4], 15.0)
FOV_Y_DEG = 65.0
SEGMENT = {WALL: 1, FLOOR: 2, CEILING: 3}
OBJECT = 4
LABELS = {1: ("wall", "walls"), 2: ("floor", "floor"), 3: ("ceiling", "ceiling"), 4: ("object", "cabinet")}


def truth_camera(width=160, height=120) -> Camera:
    """Near one wall, looking across the room and a little down: three walls, floor and ceiling
    in view (the wall behind it is not)."""
    place = lambda p: rotation_y(np.radians(TRUTH.yaw_deg)) @ np.asarray(p, float) + TRUTH.center * [1, 0, 1]  # noqa: E731
    f = 0.5 * height / np.tan(np.radians(FOV_Y_DEG) / 2)
    R, t = look_at(place([0.6, 1.4, 1.2]), place([-0.3, 1.2, -1.5]))
    return Camera("photo.exr", "PINHOLE", width, height, np.array([f, f, width / 2, height / 2]), R, t)


def box_photo(camera: Camera, noise=0.0, seed=0):
    """(classes, segments, depth, image) of TRUTH seen by ``camera``: an object (nearer, class
    object) covers a block of the back wall and floor; depth noise is relative (a monocular
    estimate's errors grow with the distance)."""
    classes, depth = cast_box(TRUTH, camera)
    segments = np.vectorize(SEGMENT.get)(classes).astype(np.int32)
    h, w = classes.shape
    block = (slice(h // 2, int(0.8 * h)), slice(int(0.3 * w), int(0.5 * w)))
    segments[block] = OBJECT
    depth[block] *= 0.7
    rng = np.random.default_rng(seed)
    depth = depth * (1 + noise * rng.standard_normal(depth.shape))
    shade = np.array([[0.6, 0.55, 0.5], [0.35, 0.25, 0.15], [0.9, 0.9, 0.9], [0.2, 0.3, 0.5]], np.float32)
    image = shade[segments - 1] / (1 + 0.1 * depth[:, :, None]).astype(np.float32)
    return np.where(segments == OBJECT, -1, classes), segments, depth.astype(np.float32), image


def write_capture(path, camera=None, noise=0.0, seed=0, depth=True, labels=None, truth=True):
    camera = camera or truth_camera()
    _, segments, depth_map, image = box_photo(camera, noise, seed)
    path.mkdir(parents=True, exist_ok=True)
    write_room_photo(path, image, depth_map if depth else None, segments, labels or LABELS, FOV_Y_DEG)
    if truth:
        (path / "truth").mkdir()
        pose = {"R": camera.R.tolist(), "t": camera.t.tolist()}  # as the room_photo generator writes it
        lens = {"width": camera.width, "height": camera.height, "fov_y_deg": FOV_Y_DEG}
        (path / "truth" / "room.json").write_text(json.dumps({"box": TRUTH.to_json(), "camera": lens | pose}))
    return path


def estimate_like(capture, out, seed=0):
    """A copy of ``capture`` whose depth looks like a monocular estimate's: an unknown scale
    (x 0.37), a smooth relative distortion of +-5 % across the image and 2 % pixel noise."""
    import shutil

    from invrender.scene.images import read_image, write_exr

    shutil.copytree(capture, out)
    depth = read_image(capture / "depth.exr")
    depth = depth[..., 0] if depth.ndim == 3 else depth
    h, w = depth.shape
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    rng = np.random.default_rng(seed)
    field = 1 + 0.05 * np.sin(2 * np.pi * (1.3 * x + 0.7 * y) + rng.uniform(0, 2 * np.pi))
    estimate = 0.37 * depth * field * (1 + 0.02 * rng.standard_normal(depth.shape))
    write_exr(out / "depth.exr", np.where(depth > 0, estimate, 0).astype(np.float32))
    return out


def study(captures: dict, work, **settings) -> list[tuple[str, tuple]]:
    """docs/room.md's table: the stage on each capture, exact and estimate-like depth; per run a
    Markdown row (corner errors in meters, all and in view; mask IoU; seconds) and
    ((name, depth), room.json's metrics)."""
    import time

    from invrender.room_box import stage

    rows = []
    for name, capture in captures.items():
        for depth, path in (("exact", capture), ("estimate-like", estimate_like(capture, work / f"{name}_estimate"))):
            started = time.perf_counter()
            report = stage.run(path, work / f"{name}_{depth}_out", truth_dir=capture / "truth", **settings)
            seconds = time.perf_counter() - started
            m = report["metrics"]
            cells = [name, depth]
            for key in ("corner_error", "visible_corner_error"):
                cells.append(f"{m['coarse'][key]:.3f} -> {m['refined'][key]:.3f}")
            for cls in ("wall", "floor", "ceiling"):
                a, b = m["coarse"]["mask_iou"][cls], m["refined"]["mask_iou"][cls]
                cells.append("-" if a is None else f"{a:.3f} -> {b:.3f}")
            cells.append(f"{m['coarse']['depth_error_relative']:.4f} -> {m['refined']['depth_error_relative']:.4f}")
            cells.append(f"{seconds:.0f}")
            rows.append(("| " + " | ".join(cells) + " |", ((name, depth), m)))
    return rows


STUDY_HEADER = [
    "| room | depth | corner error, m | in view, m | IoU wall | IoU floor | IoU ceiling | depth error (rel.) | s |",
    "|---|---|---|---|---|---|---|---|---|",
]
