"""The room stage (PSDR-Room section 4.2) on box rooms whose truth is known: the coarse fit from
clean depth, the refinement by Eq. 2 from a wrong start, the whole stage's outputs and its errors.
Inputs: tests/room_box/room_captures.py (cast exactly by room_box.box.cast_box, an object in front)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from room_captures import LABELS, TRUTH, box_photo, truth_camera, write_capture

from invrender.cli import main
from invrender.room_box import stage
from invrender.room_box.box import RoomBox, cast_box, rotation_y
from invrender.room_box.coarse import CoarseSettings, fit_coarse_box
from invrender.room_box.metrics import truth_metrics
from invrender.room_box.refine import RefineSettings, reduced_targets, refine_box
from invrender.scene.images import write_exr
from invrender.scene.types import SceneError


def test_cast_box_sees_the_truth_from_inside():
    """The reference render: a pixel's depth is where its ray leaves the box (checked against the
    planes' equations), its label the face it leaves by."""
    camera = truth_camera(40, 30)
    labels, depth = cast_box(TRUTH, camera)
    assert (labels >= 0).all() and set(np.unique(labels)) == {0, 1, 2}
    from invrender.scene.cameras import pixel_directions

    points = camera.center + pixel_directions(camera) * depth[:, :, None]
    local = (points - TRUTH.center) @ np.array(
        [
            [np.cos(np.radians(15)), 0, -np.sin(np.radians(15))],
            [0, 1, 0],
            [np.sin(np.radians(15)), 0, np.cos(np.radians(15))],
        ]
    ).T
    on_face = np.abs(np.abs(local) - TRUTH.size / 2).min(axis=2)
    assert on_face.max() < 1e-9
    assert np.allclose(local[labels == 1][:, 1], -TRUTH.size[1] / 2) and np.allclose(
        local[labels == 2][:, 1], TRUTH.size[1] / 2
    )


def test_coarse_fit_recovers_the_box_from_clean_depth():
    """Floor plane, height and the walls in view from exact depth: the corners the photo shows
    within 2 cm (measured 0.2 cm), the floor's normal within 0.1 degree, the height within 1 cm."""
    camera = truth_camera()
    classes, _, depth, _ = box_photo(camera)
    fit = fit_coarse_box(depth, classes, camera, CoarseSettings(), seed=0)
    metrics = truth_metrics(fit.box, fit.camera, TRUTH, camera)
    assert metrics["visible_corners"] >= 2
    assert metrics["visible_corner_error"] < 0.02, metrics
    up = camera.R @ [0.0, 1.0, 0.0]  # the truth's +Y in the camera frame
    assert np.degrees(np.arccos(np.clip(up @ fit.floor["normal"], -1, 1))) < 0.1
    assert fit.floor["offset"] == pytest.approx(camera.center[1], abs=0.01)
    assert fit.ceiling_seen and fit.box.size[1] == pytest.approx(TRUTH.size[1], abs=0.01)
    # The camera is inside, and the sizes are at most the truth's (a side not in view is put
    # just behind the camera, never beyond the room's points).
    assert (np.abs(fit.camera.center - fit.box.center)[[0, 2]] < fit.box.size[[0, 2]] / 2).all()


def test_without_a_ceiling_the_height_is_1_2_times_the_top_point():
    camera = truth_camera()
    classes, _, depth, _ = box_photo(camera)
    classes = np.where(classes == 2, -1, classes)
    fit = fit_coarse_box(depth, classes, camera, CoarseSettings(), seed=0)
    assert not fit.ceiling_seen
    # The walls reach the ceiling; their top points, after the erosion and the percentile, lie
    # within 10 cm below it (measured: 1.2 x 2.618 for 2.7).
    assert 1.2 * (TRUTH.size[1] - 0.1) < fit.box.size[1] <= 1.2 * TRUTH.size[1]


def test_refinement_lowers_the_corner_error_from_a_wrong_start():
    """2 % depth noise, a start 8 degrees off in yaw, 10 % off in size and 20 cm off in place:
    Eq. 2 through render_masks_depth brings the corners in view from 22 cm to within 5 cm (measured
    2.8 cm), and the mean over all eight corners down (measured 0.48 -> 0.22 m: the sides behind the
    camera have no gradient and keep the start's error)."""
    camera = truth_camera()
    classes, _, depth, _ = box_photo(camera, noise=0.02, seed=3)
    start = RoomBox(TRUTH.center + [0.2, -0.05, -0.15], TRUTH.size * [0.9, 1.05, 1.1], TRUTH.yaw_deg + 8.0)
    targets = reduced_targets(classes, depth.astype(np.float64), camera, 64)
    refined, history = refine_box(start, targets, RefineSettings(iterations=40, learning_rate=0.04), seed=0)
    before, after = truth_metrics(start, camera, TRUTH, camera), truth_metrics(*refined.upright(camera), TRUTH, camera)
    assert (
        after["visible_corner_error"] < 0.05 and after["visible_corner_error"] < 0.25 * before["visible_corner_error"]
    )
    assert after["corner_error"] < before["corner_error"]
    assert history[-1]["loss"] < history[0]["loss"]


def test_stage_writes_the_box_the_camera_and_both_fits_metrics(tmp_path):
    """The whole stage on a noisy capture: room.json in the depth's units (meters here) in the
    refined box's world (yaw 0, floor y = 0), whose camera re-casts the photo's labels; metrics
    of both boxes against the truth; the figure."""
    capture = write_capture(tmp_path / "capture", noise=0.01)
    out = tmp_path / "room_box"
    report = stage.run(capture, out, refine=RefineSettings(iterations=20, max_width=64))
    assert json.loads((out / "room.json").read_text()) == report
    box = RoomBox.from_json(report["box"])
    assert (
        box.yaw_deg == 0 and box.center[[0, 2]].tolist() == [0, 0] and box.center[1] == pytest.approx(box.size[1] / 2)
    )
    camera = truth_camera()
    camera.R, camera.t = np.array(report["camera"]["R"]), np.array(report["camera"]["t"])
    assert report["camera"]["center"][1] == pytest.approx(truth_camera().center[1], abs=0.02)  # the height, meters
    classes, _, _, _ = box_photo(truth_camera())
    labels = cast_box(box, camera)[0]
    assert (labels == classes)[classes >= 0].mean() > 0.99
    assert len(report["losses"]) == 20 and report["truth"] == str(capture / "truth")
    for which in ("coarse", "refined"):
        m = report["metrics"][which]
        assert set(m["mask_iou"]) == {"wall", "floor", "ceiling"} and min(m["mask_iou"].values()) > 0.95
        assert m["visible_corner_error"] < 0.05 and m["corner_error"] < 0.5, m  # meters
        assert m["depth_error_relative"] < 0.02  # the noise is 1 % of each depth
    figure = cv2.imread(str(out / "room_box.png"))
    assert figure.shape == (2 * 480, 2 * 640, 3)  # 2 x 2 panels, 160 x 120 enlarged 4 times
    assert (out / ".invrender-output").read_text().strip() == "room_box"


def test_cli_runs_the_stage_and_names_a_missing_depth(tmp_path):
    capture = write_capture(tmp_path / "capture")
    args = ["room-box", str(capture), "--out", str(tmp_path / "out"), "--iterations", "2", "--max-width", "32"]
    assert main(args) == 0 and (tmp_path / "out" / "room.json").is_file()
    (capture / "depth.exr").unlink()
    assert main([*args[:3], str(tmp_path / "out2"), *args[4:]]) == 2
    assert not (tmp_path / "out2").exists()


def _error(tmp_path, **capture) -> SceneError:
    path = write_capture(tmp_path / "capture", truth=False, **capture)
    with pytest.raises(SceneError) as error:
        stage.run(path, tmp_path / "out", refine=RefineSettings(iterations=1, max_width=32))
    assert not (tmp_path / "out").exists()
    return error.value


def test_no_depth_says_what_to_provide(tmp_path):
    error = _error(tmp_path, depth=False)
    assert error.field == "depth" and "depth.exr" in error.expected


def test_a_depth_of_zeros_is_refused(tmp_path):
    path = write_capture(tmp_path / "capture", truth=False)
    write_exr(path / "depth.exr", np.zeros((120, 160), np.float32))
    with pytest.raises(SceneError, match="positive depth"):
        stage.run(path, tmp_path / "out")


def test_no_floor_points_is_refused_naming_the_segmentation(tmp_path):
    """The floor labelled as an object: nothing to fit the floor plane to."""
    labels = dict(LABELS) | {2: ("object", "rug")}
    error = _error(tmp_path, labels=labels)
    assert error.field == "floor" and error.file.endswith("panoptic.png") and "got 0" in error.expected


def test_unknown_coarse_setting_is_named():
    with pytest.raises(SceneError, match="treshold"):
        CoarseSettings.from_overrides({"treshold": 0.1})


# The study behind docs/room.md's table (three synthesized rooms at 1024 x 768, about 15 minutes):
#   PYTHONPATH=workflow python -m pytest tests/room_box/test_room_box.py -m benchmark -s -n 0
@pytest.mark.benchmark
def test_study_of_the_room_stage(tmp_path):
    from room_captures import STUDY_HEADER, study

    from invrender.synthesize import stage as synthesize

    captures = {}
    for layout in ("living", "bedroom", "office"):
        captures[layout] = tmp_path / layout
        synthesize.run("room_photo", captures[layout], {"layout": layout}, spp=4, seed=0)
    rows = study(captures, tmp_path)
    print("\n" + "\n".join(STUDY_HEADER + [row for row, _ in rows]))
    metrics = {key: m for _, (key, m) in rows}
    for layout in captures:
        exact, estimate = metrics[(layout, "exact")], metrics[(layout, "estimate-like")]
        # Measured: exact depth puts the corners in view within 1.1 cm (the lowest of the noisy
        # losses is not always the coarse box's 0.3 cm), except the office's: one
        # is a ceiling corner at the frame's edge, and no ceiling is seen (the 1.2x height: the
        # coarse fit 21 cm off; refined 15 or 32 cm in two runs, as nothing constrains it).
        if layout == "office":
            assert exact["coarse"]["visible_corner_error"] < 0.25
        else:
            assert exact["refined"]["visible_corner_error"] < 0.02
        # Estimate-like depth: the refinement raises every class's IoU (measured 0.69-0.995 ->
        # 0.99-0.999); the corners in view improve in the living room and bedroom (0.24 -> 0.03,
        # 0.44 -> 0.04 m), not in the office, whose height no term constrains (0.48 -> 0.51).
        for cls, iou in estimate["refined"]["mask_iou"].items():
            assert iou is None or iou > estimate["coarse"]["mask_iou"][cls]
        if layout != "office":
            assert estimate["refined"]["visible_corner_error"] < 0.5 * estimate["coarse"]["visible_corner_error"]


def test_refinement_keeps_the_camera_inside_the_box():
    """A side that crosses the camera (here the start's wall behind it) is projected back beyond
    it after the first step: seen from outside, the box would cover the photo with one wall."""
    camera = truth_camera()
    classes, _, depth, _ = box_photo(camera)
    start = RoomBox(TRUTH.center, TRUTH.size, TRUTH.yaw_deg)
    local = rotation_y(np.radians(-TRUTH.yaw_deg)) @ (camera.center - TRUTH.center)
    start.size[2] = 2 * abs(local[2]) - 0.2  # the camera 10 cm outside the +z or -z side
    assert not (np.abs(local) < start.size / 2).all()
    targets = reduced_targets(classes, depth.astype(np.float64), camera, 32)
    refined, _ = refine_box(start, targets, RefineSettings(iterations=1), seed=0)
    box, posed = refined.upright(camera)
    assert (np.abs(posed.center - box.center) <= box.size / 2 - 0.05 + 1e-9).all()
