"""The cameras stage writes cameras/images/, the one folder of images every later stage reads:
each pinhole camera's image a hard link of the capture's (a copy across file systems), checked
first; an image of another size, a NaN or infinite pixel or a missing image stops the stage with
one line naming the file, and nothing is written."""

import errno
import json
import os
import re

import cv2
import numpy as np
import pytest

import invrender.cameras.stage as stage
from invrender.cli import main
from invrender.scene.cameras import read_cameras, write_colmap
from invrender.scene.capture import read_view
from invrender.scene.images import srgb_to_linear, write_exr
from invrender.scene.types import Camera

LOG_LINE = re.compile(r"^\S+ \S+ invrender [A-Z]+ ")


def pinhole(name, width=8, height=6, z=3.0):
    """A camera at (0, 0, -z) looking along +z."""
    f = float(width)
    return Camera(
        name, "PINHOLE", width, height, np.array([f, f, width / 2, height / 2]), np.eye(3), np.array([0, 0, z])
    )


@pytest.fixture
def capture(tmp_path):
    """A COLMAP capture: two cameras, their EXR images (and a PNG preview beside one, which the
    stage must leave out)."""
    rng = np.random.default_rng(1)
    cameras = [pinhole("a.exr"), pinhole("b.exr", z=2.0)]
    write_colmap(tmp_path / "sparse", cameras)
    (tmp_path / "images").mkdir()
    for camera in cameras:
        write_exr(tmp_path / "images" / camera.name, rng.uniform(0, 4, (camera.height, camera.width, 3)))
    cv2.imwrite(str(tmp_path / "images" / "a.png"), np.zeros((6, 8, 3), np.uint8))
    return tmp_path


def cameras_cli(capture, out, *more):
    return main(["cameras", str(capture / "sparse"), "--out", str(out), "--images", str(capture / "images"), *more])


def test_images_are_hard_links_of_the_capture_named_as_the_cameras(capture, tmp_path):
    out = tmp_path / "cameras"
    assert cameras_cli(capture, out) == 0
    assert sorted(p.name for p in (out / "images").iterdir()) == ["a.exr", "b.exr"]
    for name in ("a.exr", "b.exr"):
        assert (out / "images" / name).samefile(capture / "images" / name)
        assert os.stat(capture / "images" / name).st_nlink == 2
    written = read_cameras(out)
    assert [c.name for c in written] == ["a.exr", "b.exr"]
    for camera in written:
        np.testing.assert_array_equal(read_view(out / "images", camera), read_view(capture / "images", camera))
    # and again over its own output: the old links go, the new ones are there
    assert cameras_cli(capture, out) == 0
    assert os.stat(capture / "images" / "a.exr").st_nlink == 2


def test_across_file_systems_the_image_is_copied(capture, tmp_path, monkeypatch):
    def cross_device(source, target):
        raise OSError(errno.EXDEV, "Invalid cross-device link")

    monkeypatch.setattr(stage.os, "link", cross_device)
    out = tmp_path / "cameras"
    stage.run(capture / "sparse", out, capture / "images", progress=False)
    copy, original = out / "images" / "a.exr", capture / "images" / "a.exr"
    assert not copy.samefile(original) and copy.read_bytes() == original.read_bytes()


def test_without_images_only_the_model_is_written(capture, tmp_path):
    out = tmp_path / "cameras"
    assert main(["cameras", str(capture / "sparse"), "--out", str(out)]) == 0
    assert not (out / "images").exists() and len(read_cameras(out)) == 2


def _nan(path):
    image = np.ones((6, 8, 3), np.float32)
    image[2, 5, 1] = np.nan
    write_exr(path, image)


def _inf(path):
    image = np.ones((6, 8, 3), np.float32)
    image[0, 7, 2] = np.inf
    write_exr(path, image)


@pytest.mark.parametrize(
    "spoil, expected",
    [
        (
            lambda path: write_exr(path, np.ones((6, 9, 3), np.float32)),
            "b.exr: size: expected 8 x 6 as its camera says, got 9 x 6",
        ),
        (_nan, "b.exr: pixel (x 5, y 2) channel 1: expected finite values, got nan"),
        (_inf, "b.exr: pixel (x 7, y 0) channel 2: expected finite values, got inf"),
        (os.unlink, "b.exr: image of camera b.exr: expected an image for every camera of the model"),
    ],
    ids=["size", "nan", "inf", "missing"],
)
def test_a_bad_image_stops_the_stage_with_one_line_naming_it(capture, tmp_path, capsys, spoil, expected):
    spoil(capture / "images" / "b.exr")
    out = tmp_path / "cameras"
    assert cameras_cli(capture, out) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if LOG_LINE.match(line)]  # not tqdm's bar
    assert len(lines) == 1 and f"invrender ERROR {capture / 'images' / expected}" in lines[0], err
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".cameras")]


def test_a_transforms_json_capture_with_srgb_png_images(tmp_path):
    """nerfstudio's layout: transforms.json beside images/, file_path "images/x.png". The names
    become relative to the images folder (as COLMAP's are), the PNGs are linked as they are, and
    read back they are the sRGB-decoded linear values."""
    rng = np.random.default_rng(2)
    c2w = np.eye(4)
    c2w[2, 3] = 3.0
    frames, pngs = [], {}
    (tmp_path / "images").mkdir()
    for name in ("x", "y"):
        pngs[name] = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)  # RGB
        cv2.imwrite(str(tmp_path / "images" / f"{name}.png"), pngs[name][:, :, ::-1])
        frames.append({"file_path": f"images/{name}.png", "transform_matrix": c2w.tolist()})
    doc = {"fl_x": 8, "fl_y": 8, "cx": 4, "cy": 3, "w": 8, "h": 6, "frames": frames}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    out = tmp_path / "cameras"
    assert (
        main(["cameras", str(tmp_path / "transforms.json"), "--out", str(out), "--images", str(tmp_path / "images")])
        == 0
    )
    written = read_cameras(out)
    assert [c.name for c in written] == ["x.png", "y.png"]
    for camera, name in zip(written, ("x", "y")):
        assert (out / "images" / camera.name).samefile(tmp_path / "images" / f"{name}.png")
        np.testing.assert_allclose(read_view(out / "images", camera), srgb_to_linear(pngs[name] / 255.0), rtol=1e-6)


def test_an_image_name_leaving_the_images_folder_is_refused(tmp_path):
    (tmp_path / "images").mkdir()
    write_exr(tmp_path / "x.exr", np.ones((6, 8, 3), np.float32))
    write_colmap(tmp_path / "sparse", [pinhole("../x.exr")])
    with pytest.raises(Exception, match=r"camera \.\./x\.exr image name: expected a relative path without '\.\.'"):
        stage.run(tmp_path / "sparse", tmp_path / "cameras", tmp_path / "images", progress=False)
    assert not (tmp_path / "cameras").exists()
