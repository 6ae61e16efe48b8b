"""A small synthetic room photo with furniture whose truth is known, for the room_objects tests:
a box room (room_box.box.cast_box) and assets of the library placed in it (the room generator's
placement: world = R_y(yaw) (scale * unit mesh) + position), seen exactly by assets/raster.py's
z-buffer; each object a segment of its own; the depth the nearer of the two. Written in
scene/room_photo.py's layout with truth/room.json (objects with their segment ids, the camera),
and beside it a room_box output (room.json: the true box and camera, depth_scale) so that the
object stage is tested on its own."""

from __future__ import annotations

import json

import numpy as np

from invrender.assets import library
from invrender.assets.raster import render_depth
from invrender.room_box.box import CEILING, FLOOR, WALL, RoomBox, cast_box
from invrender.scene.cameras import pinhole_camera
from invrender.scene.room_photo import write_room_photo, yaw_matrix

BOX = RoomBox([0.0, 1.35, 0.0], [5.0, 2.7, 4.0], 0.0)
SHELL = {WALL: 1, FLOOR: 2, CEILING: 3}
LABELS = {1: ("wall", "walls"), 2: ("floor", "floor"), 3: ("ceiling", "ceiling")}
# name, asset, scale (largest extent, m), (x, z) or None on its support, yaw, support name
OBJECTS = [
    ("coffee_table", "table_a", 1.1, (-0.6, -0.3), 80.0, "floor"),
    ("crate", "box_a", 0.3, (-0.55, -0.25), 20.0, "coffee_table"),
    ("armchair", "chair_c", 0.87, (0.9, -0.4), 215.0, "floor"),
]
FOV_Y_DEG = 55.0


def camera(width=240, height=180):
    fov_x = float(np.degrees(2 * np.arctan(np.tan(np.radians(FOV_Y_DEG) / 2) * width / height)))
    return pinhole_camera("photo.exr", [1.6, 1.5, 1.5], [-0.4, 0.6, -1.2], width, height, fov_x)


def placements():
    """The truth: each object's asset, position (footprint centre on its support), yaw, scale."""
    assets = {a.name: a for a in library()}
    placed = {}
    for name, asset_name, scale, xz, yaw, support in OBJECTS:
        asset = assets[asset_name]
        y = 0.0 if support == "floor" else placed[support]["top"]
        placed[name] = {
            "asset": asset,
            "position": np.array([xz[0], y, xz[1]]),
            "yaw_deg": yaw,
            "scale": scale,
            "support": support,
            "top": y + scale * asset.extent[1],
        }
    return placed


def photo(cam, objects=True):
    """(segments, depth, image, labels, truth objects) of the room seen by ``cam``."""
    classes, depth = cast_box(BOX, cam)
    segments = np.vectorize(SHELL.get)(classes).astype(np.int32)
    labels = dict(LABELS)
    truth = []
    placed = placements() if objects else {}
    for k, (name, p) in enumerate(placed.items()):
        sid = 4 + k
        world = (p["asset"].mesh.positions * p["scale"]) @ yaw_matrix(p["yaw_deg"]).T + p["position"]
        z, face = render_depth(world, p["asset"].mesh.faces, cam)
        nearer = (face >= 0) & (z < depth)
        segments[nearer], depth[nearer] = sid, z[nearer]
        labels[sid] = ("object", name)
        support = p["support"] if p["support"] == "floor" else str(4 + list(placed).index(p["support"]))
        truth.append(
            {
                "segment": sid,
                "name": name,
                "asset": p["asset"].name,
                "category": p["asset"].category,
                "position": p["position"].tolist(),
                "yaw_deg": p["yaw_deg"],
                "scale": p["scale"],
                "support": support,
            }
        )
    shade = np.random.default_rng(0).uniform(0.2, 0.9, (len(labels) + 1, 3)).astype(np.float32)
    image = shade[segments] / (1 + 0.1 * depth[:, :, None]).astype(np.float32)
    return segments, depth.astype(np.float32), image, labels, truth


def write_capture(path, cam=None, objects=True, depth=True):
    """The capture (with truth/) at ``path`` and the room_box output at ``path``/../room_box."""
    cam = cam or camera()
    segments, depth_map, image, labels, truth = photo(cam, objects)
    path.mkdir(parents=True)
    write_room_photo(path, image, depth_map if depth else None, segments, labels, FOV_Y_DEG)
    (path / "truth").mkdir()
    pose = {"R": cam.R.tolist(), "t": cam.t.tolist()}
    lens = {"width": cam.width, "height": cam.height, "fov_y_deg": FOV_Y_DEG}
    (path / "truth" / "room.json").write_text(
        json.dumps({"box": BOX.to_json(), "camera": lens | pose, "objects": truth})
    )
    room = path.parent / "room_box"
    room.mkdir(exist_ok=True)
    (fx, fy), (cx, cy) = cam.focal, cam.principal_point
    room_camera = {"width": cam.width, "height": cam.height, "params": [fx, fy, cx, cy]} | pose
    scale = float(np.median(depth_map[depth_map > 0]))
    (room / "room.json").write_text(json.dumps({"box": BOX.to_json(), "camera": room_camera, "depth_scale": scale}))
    return path, room


def study(runs: dict, work, **settings) -> list[tuple[str, dict]]:
    """docs/room-objects.md's table: the stage on each (capture, room_box output) of ``runs``; per
    run a Markdown row (coarse -> refined: asset and category accuracy, position error m, yaw error
    degrees, scale error, mean mask IoU; seconds) and objects.json's metrics."""
    import time

    from invrender.room_objects import stage

    rows = []
    for name, (capture, room) in runs.items():
        started = time.perf_counter()
        report = stage.run(capture, room, work / f"{name}_objects", stage.Settings(**settings))
        seconds = time.perf_counter() - started
        m = report["metrics"]
        cells = [name, str(len(report["objects"]))]
        for key, digits in (
            ("asset_accuracy", 2),
            ("category_accuracy", 2),
            ("position_error", 3),
            ("yaw_error_deg", 1),
            ("scale_error", 3),
            ("mean_mask_iou", 3),
        ):
            cells.append(f"{m['coarse'][key]:.{digits}f} -> {m['refined'][key]:.{digits}f}")
        cells.append(f"{seconds:.0f}")
        rows.append(("| " + " | ".join(cells) + " |", m))
    return rows


STUDY_HEADER = [
    "| room | objects | asset top-1 | category top-1 | position error, m | yaw error, deg | scale error | mask IoU "
    "| s |",
    "|---|---|---|---|---|---|---|---|---|",
]
