"""segment's provided backend and the stage's refusals: masks from any tool round-trip (an id
image, a folder of per-instance PNGs), ids renumbered in reading order with the original kept,
and every bad input stops with one SceneError naming the file, the field and what was expected,
leaving nothing behind."""

import json

import cv2
import numpy as np
import pytest

from invrender.cli import main
from invrender.scene.images import read_mask, write_mask
from invrender.scene.types import SceneError
from invrender.segment import run
from invrender.segment.stage import renumber

W, H = 40, 30
# Three rectangles, given ids in no particular order: (source id, x0, y0, x1, y1), x1/y1 exclusive.
RECTS = [(7, 22, 3, 30, 12), (3, 2, 14, 12, 26), (12, 4, 2, 14, 9)]


def id_image(rects=RECTS, size=(W, H)) -> np.ndarray:
    ids = np.zeros(size[::-1], np.uint16)
    for value, x0, y0, x1, y1 in rects:
        ids[y0:y1, x0:x1] = value
    return ids


@pytest.fixture
def photo(tmp_path):
    path = tmp_path / "photo.png"
    rng = np.random.default_rng(0)
    cv2.imwrite(str(path), rng.integers(0, 255, (H, W, 3), dtype=np.uint8))
    return path


def entries(folder):
    return sorted(p.name for p in folder.iterdir())


def test_id_image_round_trips_renumbered_in_reading_order(tmp_path, photo):
    write_mask(tmp_path / "ids.png", id_image())
    report = run(photo, tmp_path / "seg", backend="provided", masks=tmp_path / "ids.png")
    out = read_mask(tmp_path / "seg" / "masks" / "photo.png")
    # Reading order of the top-left corners (y, then x): 12 at y 2, 7 at y 3, 3 at y 14.
    order = [12, 7, 3]
    expected = np.zeros_like(out)
    for new, old in enumerate(order, 1):
        expected[id_image() == old] = new
    np.testing.assert_array_equal(out, expected)
    assert out.dtype == np.uint16
    written = json.loads((tmp_path / "seg" / "instances.json").read_text())
    assert written == report
    assert (written["width"], written["height"], written["backend"]) == (W, H, "provided")
    boxes = {r[0]: list(r[1:]) for r in RECTS}
    for entry, old in zip(written["instances"], order):
        assert entry["source"] == old
        assert entry["box"] == boxes[old]
        x0, y0, x1, y1 = boxes[old]
        assert entry["area"] == (x1 - x0) * (y1 - y0)
        assert entry["score"] == 1.0
    assert [e["id"] for e in written["instances"]] == [1, 2, 3]
    overlay = cv2.imread(str(tmp_path / "seg" / "overlay.png"))
    assert overlay.shape[1] >= 640 and overlay.shape[1] % W == 0  # enlarged by a whole factor


def test_eight_bit_id_image_and_a_table_that_lists_its_ids(tmp_path, photo):
    cv2.imwrite(str(tmp_path / "ids8.png"), id_image().astype(np.uint8))
    (tmp_path / "table.csv").write_text("id,label\n3,can\n7,can\n12,can\n")
    run(photo, tmp_path / "a", backend="provided", masks=tmp_path / "ids8.png", table=tmp_path / "table.csv")
    (tmp_path / "table.json").write_text(json.dumps({"instances": [{"id": 3}, {"id": 7}, {"id": 12}, {"id": 13}]}))
    run(photo, tmp_path / "b", backend="provided", masks=tmp_path / "ids8.png", table=tmp_path / "table.json")
    for name in ("a", "b"):
        assert read_mask(tmp_path / name / "masks" / "photo.png").max() == 3


def test_folder_of_masks_round_trips(tmp_path, photo):
    folder = tmp_path / "masks"
    folder.mkdir()
    for value, x0, y0, x1, y1 in RECTS:
        mask = np.zeros((H, W), np.uint8)
        mask[y0:y1, x0:x1] = 255
        cv2.imwrite(str(folder / f"can_{value:02d}.png"), mask)
    report = run(photo, tmp_path / "seg", backend="provided", masks=folder)
    out = read_mask(tmp_path / "seg" / "masks" / "photo.png")
    names = {"can_12.png": 1, "can_07.png": 2, "can_03.png": 3}
    for value, x0, y0, x1, y1 in RECTS:
        assert np.all(out[y0:y1, x0:x1] == names[f"can_{value:02d}.png"])
    assert (out > 0).sum() == sum((x1 - x0) * (y1 - y0) for _, x0, y0, x1, y1 in RECTS)
    assert {e["source"]: e["id"] for e in report["instances"]} == names


def test_renumber_breaks_ties_by_x_then_old_id():
    ids = np.zeros((4, 6), np.uint16)
    ids[0, 4], ids[0, 1], ids[2, 0] = 9, 5, 2
    new, old_of = renumber(ids)
    assert old_of == {1: 5, 2: 9, 3: 2}
    assert new[0, 1] == 1 and new[0, 4] == 2 and new[2, 0] == 3


def refused(tmp_path, photo, **kwargs) -> SceneError:
    before = entries(tmp_path)
    with pytest.raises(SceneError) as caught:
        run(photo, tmp_path / "seg", **kwargs)
    assert entries(tmp_path) == before  # no output, no temporary beside it
    return caught.value


def test_ids_beyond_the_table_stop(tmp_path, photo):
    write_mask(tmp_path / "ids.png", id_image())
    (tmp_path / "table.json").write_text(json.dumps([3, 7]))
    error = refused(tmp_path, photo, backend="provided", masks=tmp_path / "ids.png", table=tmp_path / "table.json")
    assert error.file == str(tmp_path / "ids.png") and error.field == "instance ids"
    assert "table.json lists (3, 7)" in error.expected and "found 12 beyond it" in error.expected


def test_a_table_that_is_not_one_stops(tmp_path, photo):
    write_mask(tmp_path / "ids.png", id_image())
    (tmp_path / "table.csv").write_text("name\ncan\n")
    error = refused(tmp_path, photo, backend="provided", masks=tmp_path / "ids.png", table=tmp_path / "table.csv")
    assert (error.file, error.field) == (str(tmp_path / "table.csv"), "id")
    (tmp_path / "table.csv").write_text("id\n3\nseven\n")
    error = refused(tmp_path, photo, backend="provided", masks=tmp_path / "ids.png", table=tmp_path / "table.csv")
    assert error.field == "id" and "'seven'" in error.expected


def test_masks_of_another_size_stop_naming_both_sizes(tmp_path, photo):
    write_mask(tmp_path / "ids.png", id_image(size=(W + 2, H)))
    error = refused(tmp_path, photo, backend="provided", masks=tmp_path / "ids.png")
    assert (error.file, error.field) == (str(tmp_path / "ids.png"), "size")
    assert f"{W} x {H}" in error.expected and f"got {W + 2} x {H}" in error.expected
    assert str(photo) in error.expected
    folder = tmp_path / "masks"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.ones((H, W), np.uint8))
    cv2.imwrite(str(folder / "b.png"), np.ones((H + 1, W), np.uint8))
    error = refused(tmp_path, photo, backend="provided", masks=folder)
    assert (error.file, error.field) == (str(folder / "b.png"), "size") and f"got {W} x {H + 1}" in error.expected


def test_fewer_than_three_instances_stop(tmp_path, photo):
    write_mask(tmp_path / "ids.png", id_image(RECTS[:2]))
    error = refused(tmp_path, photo, backend="provided", masks=tmp_path / "ids.png")
    assert (error.file, error.field) == (str(tmp_path / "ids.png"), "instances")
    assert "at least 3 instances" in error.expected and "found 2" in error.expected


def test_settings_that_do_not_fit_the_backend_stop(tmp_path, photo):
    write_mask(tmp_path / "ids.png", id_image())
    error = refused(tmp_path, photo, backend="provided")
    assert error.field == "masks"
    error = refused(tmp_path, photo, backend="opencv", masks=tmp_path / "ids.png")
    assert error.field == "masks" and "provided" in error.expected
    error = refused(tmp_path, photo, backend="sam")
    assert error.field == "backend" and "opencv, provided" in error.expected
    error = refused(tmp_path, photo, min_instances=2)
    assert error.field == "instance count" and "at least 3" in error.expected
    error = refused(tmp_path, photo, exemplar=(10, 5, 8, 20))
    assert error.field == "exemplar box" and f"x1 <= {W}" in error.expected
    error = refused(tmp_path, photo, settings={"core_treshold": 0.2})
    assert error.field == "core_treshold" and "core_threshold" in error.expected


def test_cli_stops_with_one_line_and_status_2(tmp_path, photo, capsys):
    write_mask(tmp_path / "ids.png", id_image(RECTS[:1]))
    before = entries(tmp_path)
    status = main(
        ["segment", str(photo), "--out", str(tmp_path / "seg"), "--backend", "provided"]
        + ["--masks", str(tmp_path / "ids.png")]
    )
    assert status == 2 and entries(tmp_path) == before
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "found 1 with the provided backend" in lines[0]
