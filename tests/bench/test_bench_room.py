"""bench room: the truth's objects taken into room_box's world, and the tables."""

from __future__ import annotations

import json

import numpy as np

from invrender.bench import room as bench
from invrender.scene.room_photo import yaw_matrix
from invrender.scene.room_scene import object_transform_of, room_camera

TRUTH_CAMERA = {"width": 8, "height": 6, "fov_y_deg": 60.0, "R": yaw_matrix(20.0).tolist(), "t": [0.1, -1.4, 2.0]}
OBJECT = {"name": "chair", "asset": "chair_a", "segment": 4, "position": [0.5, 0.0, -1.0], "yaw_deg": 30, "scale": 0.8}


def test_truth_objects_land_in_room_box_world_through_the_photo_camera(tmp_path):
    # room_box's world: the truth's turned by 25 degrees about +Y, moved, and in units of 0.5 m
    # (truth_scale 2: a depth of half the size), the photo camera the same camera in it.
    W = np.eye(4)
    W[:3, :3], W[:3, 3] = yaw_matrix(25.0) / 2.0, [0.3, -0.2, 0.7]
    truth_cam = room_camera({"camera": TRUTH_CAMERA})
    to_camera = np.eye(4)
    to_camera[:3, :3], to_camera[:3, 3] = truth_cam.R, truth_cam.t
    R_box = truth_cam.R @ W[:3, :3].T * 2.0  # camera = to_camera . W^-1, scaled back
    t_box = (to_camera @ np.linalg.inv(W))[:3, 3] / 2.0
    f = 0.5 * 6 / np.tan(np.radians(30.0))
    room = {
        "box": {"center": [0, 1, 0], "size": [2, 2, 2]},
        "camera": {"width": 8, "height": 6, "params": [f, f, 4, 3], "R": R_box.tolist(), "t": t_box.tolist()},
        "metrics": {"refined": {"truth_scale": 2.0}},
    }
    capture = tmp_path / "capture"
    (capture / "truth").mkdir(parents=True)
    (capture / "truth" / "room.json").write_text(json.dumps({"camera": TRUTH_CAMERA, "objects": [OBJECT]}))
    (tmp_path / "room_box").mkdir()
    (tmp_path / "room_box" / "room.json").write_text(json.dumps(room))
    bench.truth_objects(capture, tmp_path / "room_box", tmp_path / "objects")
    (placed,) = json.loads((tmp_path / "objects" / "objects.json").read_text())["objects"]
    assert np.allclose(placed["T_obj2world"], W @ object_transform_of(OBJECT, "t"))


def test_tables_show_missing_stages_and_each_accept_item(tmp_path):
    metrics = {
        "masks": {"per_class": {"wall": 0.9, "floor": 0.8}, "mean": 0.85},
        "photo": {"psnr_db": 15.0, "ssim": 0.4},
        "lights": {"power_ratio": 1.5, "power_w": {"truth": {"mean": 30.0}}, "fit": {"radiance_scale": 1.2}},
        "material": {"albedo": {"psnr_db": 14.0}, "roughness": {"mse": 0.01}, "map_mse": {"kd": 0.05}},
        "objects": {"coarse": {"asset_accuracy": 0.5, "position_error": 0.3}, "refined": {"position_error": 0.1}},
    }
    box = {"coarse": {"corner_error": 0.3, "mask_iou": {"wall": 0.9}}, "refined": {"corner_error": 0.1}}
    steps = {"room_box": {"wall_s": 30.0, "peak_rss_mb": 400.0}, "room_objects": {"missing": True}}
    row = {"scene": "living", "row": "stages", "metrics": metrics, "room_box": box, "steps": steps}
    line = bench.table_row(row)
    assert line["room_objects_s"] == "missing" and line["room_box_s"] == "30.0" and line["peak_rss_mb"] == 400.0
    assert line["asset_accuracy_coarse"] == 0.5 and line["position_error_refined"] == 0.1 and line["iou_floor"] == 0.8
    report = {"table": [line], "settings": {"width": 1024, "height": 768, "capture_spp": 16, "evaluate_spp": 16},
              "mode": "full", "seconds": 10.0, "machine": {}, "notes": []}  # fmt: skip
    text = bench.write_markdown(tmp_path, report)
    assert "Missing in this tree: room_objects" in text and "| living |" in text
    for title in ("Room box", "Objects", "Mask IoU", "Re-rendered photo", "Time per stage"):
        assert title in text
