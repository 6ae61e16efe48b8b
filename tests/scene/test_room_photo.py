"""The room photo capture (scene/room_photo.py): what it reads back, and one SceneError per bad
input, each naming the file, the field and what to provide."""

from __future__ import annotations

import json

import numpy as np
import pytest

from invrender.scene.images import write_exr, write_mask
from invrender.scene.room_photo import ROOM_CLASSES, load_room_photo, write_room_photo
from invrender.scene.types import SceneError

H, W = 12, 16
LABELS = {1: ("wall", "wall_-z"), 2: ("floor", "floor"), 3: ("object", "chair")}


def _arrays():
    rng = np.random.default_rng(0)
    image = rng.uniform(0.05, 2.0, (H, W, 3)).astype(np.float32)
    depth = rng.uniform(1.0, 5.0, (H, W)).astype(np.float32)
    depth[0, 0] = 0.0  # unknown
    ids = np.ones((H, W), np.uint16)
    ids[H // 2 :] = 2
    ids[8:10, 4:8] = 3
    ids[0, 1] = 0  # unlabelled
    return image, depth, ids


@pytest.fixture
def capture(tmp_path):
    image, depth, ids = _arrays()
    write_room_photo(tmp_path, image, depth, ids, LABELS, fov_y_deg=50.0)
    return tmp_path


def test_a_written_capture_reads_back_exactly(capture):
    image, depth, ids = _arrays()
    room = load_room_photo(capture, require=("depth", "segmentation"))
    assert room.paths["photo"].name == "photo.exr"  # the EXR, not its PNG preview
    np.testing.assert_array_equal(room.image, image)
    np.testing.assert_array_equal(room.depth, depth)
    np.testing.assert_array_equal(room.segments, ids.astype(np.int32))
    assert room.labels == LABELS
    assert room.fov_y_deg == 50.0
    assert (room.width, room.height) == (W, H)
    normalised = room.normalised_depth()
    assert np.median(normalised[depth > 0]) == pytest.approx(1.0) and normalised[0, 0] == 0
    np.testing.assert_array_equal(room.class_mask("floor"), ids == 2)


def test_a_horizontal_field_of_view_and_csv_labels_are_taken(capture):
    (capture / "camera.json").write_text(json.dumps({"width": W, "height": H, "fov_x_deg": 90.0}))
    (capture / "panoptic.json").unlink()
    (capture / "panoptic.csv").write_text("id,class,name\n1,wall,wall_-z\n2,floor,\n3,object,chair\n")
    room = load_room_photo(capture)
    # tan(fov_y / 2) = tan(45 deg) * H / W
    assert room.fov_y_deg == pytest.approx(np.degrees(2 * np.arctan(H / W)))
    assert room.labels[2] == ("floor", "floor_2")


def test_only_a_photograph_reads_with_nothing_else(tmp_path):
    write_room_photo(tmp_path, _arrays()[0])
    room = load_room_photo(tmp_path)
    assert room.depth is None and room.segments is None and room.labels is None and room.fov_y_deg is None


def _error(capture, **kwargs) -> SceneError:
    with pytest.raises(SceneError) as info:
        load_room_photo(capture, **kwargs)
    return info.value


def test_a_missing_photo_names_the_files_to_give(tmp_path):
    error = _error(tmp_path)
    assert error.field == "photo" and "photo.exr, photo.png, photo.jpg" in error.expected


def test_an_unreadable_photo_is_refused(capture):
    (capture / "photo.exr").unlink()
    (capture / "photo.png").write_bytes(b"not a PNG at all")
    error = _error(capture)
    assert error.file.endswith("photo.png") and "decode" in error.expected


def test_depth_of_another_size_is_refused(capture):
    write_exr(capture / "depth.exr", np.ones((H, W + 1), np.float32))
    error = _error(capture)
    assert error.file.endswith("depth.exr") and error.field == "size"
    assert f"{W} x {H} pixels as the photo photo.exr, got {W + 1} x {H}" in error.expected


def test_negative_depth_is_refused(capture):
    depth = np.ones((H, W), np.float32)
    depth[3, 5] = -1.0
    write_exr(capture / "depth.exr", depth)
    error = _error(capture)
    assert error.field == "pixel (x 5, y 3)" and "-1.0" in error.expected


def test_a_panoptic_id_without_a_label_is_refused(capture):
    ids = _arrays()[2]
    ids[2, 2] = 7
    write_mask(capture / "panoptic.png", ids)
    error = _error(capture)
    assert error.file.endswith("panoptic.png") and error.field == "segment id 7"
    assert "panoptic.json" in error.expected


def test_a_label_of_an_unknown_class_lists_the_classes(capture):
    rows = [{"id": 1, "class": "wall"}, {"id": 2, "class": "sofa"}, {"id": 3, "class": "object"}]
    (capture / "panoptic.json").write_text(json.dumps({"segments": rows}))
    error = _error(capture)
    assert error.file.endswith("panoptic.json") and error.field == "segments[1].class"
    assert error.expected == f"one of {', '.join(ROOM_CLASSES)}, got 'sofa'"


def test_segment_ids_without_their_label_table_name_it(capture):
    (capture / "panoptic.json").unlink()
    error = _error(capture)
    assert error.file.endswith("panoptic.png") and "panoptic.json" in error.expected


@pytest.mark.parametrize(
    "missing, files, provide",
    [
        ("depth", ("depth.exr",), ["depth.exr", "capture.depth"]),
        ("segmentation", ("panoptic.png", "panoptic.json"), ["panoptic.png", "panoptic.json", "capture.segmentation"]),
    ],
)
def test_missing_depth_or_segmentation_names_what_to_provide(capture, missing, files, provide):
    for name in files:
        (capture / name).unlink()
    assert getattr(load_room_photo(capture), "depth" if missing == "depth" else "segments") is None
    error = _error(capture, require=("depth", "segmentation"))
    assert error.field == missing
    for text in provide:
        assert text in error.expected


def test_a_camera_of_another_size_is_refused(capture):
    (capture / "camera.json").write_text(json.dumps({"width": W, "height": H + 2, "fov_y_deg": 40}))
    error = _error(capture)
    assert error.field == "height" and error.expected == f"{H} as the photo, got {H + 2}"


def test_a_photograph_without_lines_and_field_of_view_names_what_to_give(tmp_path):
    """No camera.json and nothing straight to find vanishing points in: stop, naming camera.json
    and the config key (the given field of view is returned as it is)."""
    write_room_photo(tmp_path, np.full((48, 64, 3), 0.5, np.float32))
    with pytest.raises(SceneError) as info:
        load_room_photo(tmp_path).field_of_view()
    assert info.value.field == "field of view"
    assert "camera.json with fov_y_deg" in info.value.expected and "capture.field_of_view" in info.value.expected
    assert load_room_photo(tmp_path, fov_y_deg=40.0).field_of_view() == (40.0, "given")
