"""Cameras: COLMAP round trips, transforms.json conversion checked against an OpenGL projection."""

import json
import math

import numpy as np
import pytest

from invrender.scene import Camera, SceneError
from invrender.scene.cameras import (
    cube_face_cameras,
    panorama_pixels,
    pixel_directions,
    project_points,
    read_cameras,
    write_colmap,
)
from invrender.scene.cubemap import cube_to_direction


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def some_cameras():
    rng = np.random.default_rng(3)
    specs = [
        ("c.png", "OPENCV", [512.25, 510.5, 320.1, 239.7, 0.011, -0.0023, 1e-4, -3e-4]),
        ("a.png", "PINHOLE", [600.0, 601.0, 319.5, 240.5]),
        ("b/x.exr", "SIMPLE_PINHOLE", [555.5, 320.0, 240.0]),
    ]
    return [
        Camera(
            name=n, model=m, width=640, height=480, params=np.array(p), R=random_rotation(rng), t=rng.normal(size=3) * 3
        )
        for n, m, p in specs
    ]


def test_colmap_text_roundtrip(tmp_path):
    cams = some_cameras()
    write_colmap(tmp_path / "sparse", cams)
    files = sorted(p.name for p in (tmp_path / "sparse").iterdir())
    assert {"cameras.txt", "images.txt", "points3D.txt"} <= set(files)
    back = read_cameras(tmp_path / "sparse")
    assert [c.name for c in back] == ["a.png", "b/x.exr", "c.png"]
    for c in back:
        ref = next(r for r in cams if r.name == c.name)
        assert (c.model, c.width, c.height) == (ref.model, ref.width, ref.height)
        np.testing.assert_allclose(c.R, ref.R, atol=1e-9, rtol=0)
        np.testing.assert_allclose(c.t, ref.t, atol=1e-9, rtol=0)
        np.testing.assert_allclose(c.params, ref.params, rtol=1e-15)


def test_colmap_binary_is_read(tmp_path):
    import pycolmap

    write_colmap(tmp_path / "txt", some_cameras())
    rec = pycolmap.Reconstruction(str(tmp_path / "txt"))
    (tmp_path / "bin").mkdir()
    rec.write_binary(str(tmp_path / "bin"))
    a, b = read_cameras(tmp_path / "txt"), read_cameras(tmp_path / "bin")
    for x, y in zip(a, b):
        assert x.name == y.name
        np.testing.assert_array_equal(x.R, y.R)


def test_unsupported_camera_model(tmp_path):
    write_colmap(tmp_path / "m", some_cameras()[:1])
    path = tmp_path / "m" / "cameras.txt"
    lines = [
        "1 SIMPLE_RADIAL 640 480 500 320 240 0.01" if line.startswith("1 ") else line
        for line in path.read_text().splitlines()
    ]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SceneError) as err:
        read_cameras(tmp_path / "m")
    msg = str(err.value)
    assert "cameras.txt" in msg and "camera 1 (image c.png) model" in msg and "SIMPLE_RADIAL" in msg


def test_unreadable_model(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SceneError, match="empty"):
        read_cameras(tmp_path / "empty")


def gl_pixel(c2w_gl, fx, fy, cx, cy, w, h, X, near=0.01, far=100.0):
    """Pixel of X by an OpenGL pipeline: view matrix, off-centre projection matrix, NDC, viewport."""
    view = np.linalg.inv(c2w_gl)
    P = np.array(
        [
            [2 * fx / w, 0, 1 - 2 * cx / w, 0],
            [0, 2 * fy / h, 2 * cy / h - 1, 0],
            [0, 0, -(far + near) / (far - near), -2 * far * near / (far - near)],
            [0, 0, -1, 0],
        ]
    )
    clip = P @ view @ np.append(X, 1.0)
    ndc = clip[:3] / clip[3]
    return np.array([(ndc[0] + 1) * w / 2, (1 - ndc[1]) * h / 2])  # window y points down in images


def look_at_gl(eye, target, up):
    z = eye - target
    z /= np.linalg.norm(z)  # OpenGL camera looks along -z
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, eye
    return m


def test_transforms_json_projection_matches_opengl(tmp_path):
    w, h, fx, fy, cx, cy = 800, 600, 700.0, 710.0, 390.0, 310.0
    c2w = look_at_gl(np.array([2.0, 1.5, 3.0]), np.array([0.1, 0.2, -0.3]), np.array([0.0, 1.0, 0.0]))
    doc = {
        "fl_x": fx,
        "fl_y": fy,
        "cx": cx,
        "cy": cy,
        "w": w,
        "h": h,
        "frames": [{"file_path": "./images/f0.png", "transform_matrix": c2w.tolist()}],
    }
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    (cam,) = read_cameras(tmp_path / "transforms.json")
    assert cam.name == "images/f0.png" and cam.model == "PINHOLE"
    assert (cam.width, cam.height) == (w, h)
    np.testing.assert_allclose(cam.center, c2w[:3, 3], atol=1e-12)
    for X in ([0.3, 0.1, -0.2], [0.1, 0.2, -0.3], [-0.4, 0.9, 0.5]):
        X = np.array(X)
        np.testing.assert_allclose(project_points(cam, X)[0], gl_pixel(c2w, fx, fy, cx, cy, w, h, X), atol=1e-6)
    # OpenCV z points forward: the look-at target is in front of the camera
    assert (cam.R @ np.array([0.1, 0.2, -0.3]) + cam.t)[2] > 0


def test_transforms_json_camera_angle_and_image_size(tmp_path):
    import cv2

    (tmp_path / "train").mkdir()
    cv2.imwrite(str(tmp_path / "train" / "r_0.png"), np.zeros((20, 40, 3), np.uint8))
    angle = 0.6911112070083618
    doc = {"camera_angle_x": angle, "frames": [{"file_path": "./train/r_0", "transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    (cam,) = read_cameras(tmp_path)  # a directory holding a transforms.json
    assert cam.name == "train/r_0.png" and (cam.width, cam.height) == (40, 20)
    f = 0.5 * 40 / math.tan(0.5 * angle)
    np.testing.assert_allclose(cam.params, [f, f, 20, 10])
    np.testing.assert_allclose(cam.R, np.diag([1.0, -1.0, -1.0]))


def test_transforms_json_distortion_and_errors(tmp_path):
    base = {"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480}
    frame = {"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}
    p = tmp_path / "transforms.json"
    p.write_text(json.dumps({**base, "k1": 0.1, "p2": 0.01, "frames": [frame]}))
    (cam,) = read_cameras(p)
    assert cam.model == "OPENCV"
    np.testing.assert_allclose(cam.params, [500, 500, 320, 240, 0.1, 0, 0, 0.01])
    p.write_text(json.dumps({**base, "camera_model": "OPENCV_FISHEYE", "frames": [frame]}))
    with pytest.raises(SceneError, match=r"transforms\.json: camera_model: expected one of .* got OPENCV_FISHEYE"):
        read_cameras(p)
    scaled = {**frame, "transform_matrix": (2 * np.eye(4)).tolist()}
    p.write_text(json.dumps({**base, "frames": [scaled]}))
    with pytest.raises(SceneError, match=r"frames\[0\]\.transform_matrix"):
        read_cameras(p)


def test_transforms_json_to_colmap_roundtrip(tmp_path):
    c2w = look_at_gl(np.array([1.0, 2.0, 3.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    doc = {"fl_x": 300, "w": 64, "h": 48, "frames": [{"file_path": "x.png", "transform_matrix": c2w.tolist()}]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    cams = read_cameras(tmp_path / "transforms.json")
    write_colmap(tmp_path / "sparse", cams)
    back = read_cameras(tmp_path / "sparse")
    np.testing.assert_allclose(back[0].R, cams[0].R, atol=1e-9)
    np.testing.assert_allclose(back[0].t, cams[0].t, atol=1e-9)


# ---------------------------------------------------------------------------- panoramas


def test_panorama_pixels_are_colmaps_equirectangular_projection():
    import pycolmap

    rng = np.random.default_rng(5)
    directions = rng.normal(size=(500, 3))
    colmap = pycolmap.Camera(camera_id=1, model="EQUIRECTANGULAR", width=300, height=140, params=[300, 140])
    np.testing.assert_allclose(panorama_pixels(directions, 300, 140), colmap.img_from_cam(directions), atol=1e-9)


def test_cube_face_images_are_mirrored_cube_map_faces_turned_with_the_panorama():
    """Face k of cube_face_cameras sees face k of the kg cube map (scene/cubemap.py), left to
    right mirrored: pixel (row r, column c) looks along the texel (r, N - 1 - c)'s direction."""
    n = 6
    rows, cols = np.mgrid[0:n, 0:n] + 0.5
    for k, face in enumerate(cube_face_cameras([1.0, 2.0, 3.0], n)):
        d = pixel_directions(face)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        np.testing.assert_allclose(d, cube_to_direction(k, (n - cols) / n, rows / n), atol=1e-12)
    turn = random_rotation(np.random.default_rng(6))  # world-to-panorama
    for plain, turned in zip(cube_face_cameras([0, 0, 0], n), cube_face_cameras([0, 0, 0], n, rotation=turn)):
        np.testing.assert_allclose(pixel_directions(turned), pixel_directions(plain) @ turn, atol=1e-12)


def equirectangular_model(tmp_path, params=(64, 32)):
    import pycolmap

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="EQUIRECTANGULAR", width=64, height=32, params=list(params))
    )
    rec.add_image_with_trivial_frame(pycolmap.Image(name="p.jpg", camera_id=1, image_id=1), pycolmap.Rigid3d())
    rec.write_text(str(tmp_path))
    return tmp_path


def test_panoramas_are_read_only_for_the_cameras_stage(tmp_path):
    model = equirectangular_model(tmp_path)
    with pytest.raises(SceneError, match=r"got EQUIRECTANGULAR \(EQUIRECTANGULAR panoramas: `invrender cameras"):
        read_cameras(model)
    (pano,) = read_cameras(model, panoramas=True)
    assert (pano.model, pano.width, pano.height, pano.params.tolist()) == ("EQUIRECTANGULAR", 64, 32, [64, 32])


def test_a_panorama_that_is_not_the_full_sphere_is_refused(tmp_path):
    (tmp_path / "crop").mkdir()
    with pytest.raises(SceneError, match=r"cameras\.txt: camera 1 \(image p\.jpg\) params: expected w, h equal to"):
        read_cameras(equirectangular_model(tmp_path / "crop", params=(80, 32)), panoramas=True)
    frame = {"file_path": "p.jpg", "transform_matrix": np.eye(4).tolist()}
    doc = {"camera_model": "EQUIRECTANGULAR", "w": 64, "h": 32, "fl_x": 32, "fl_y": 32, "frames": [frame]}
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    (pano,) = read_cameras(tmp_path / "transforms.json", panoramas=True)  # fl_x = w / 2, fl_y = h: nerfstudio's
    assert pano.params.tolist() == [64, 32]
    (tmp_path / "transforms.json").write_text(json.dumps({**doc, "fl_y": 20}))
    with pytest.raises(SceneError, match=r"frames\[0\] fl_y: expected 32 for an EQUIRECTANGULAR camera of 64 x 32"):
        read_cameras(tmp_path / "transforms.json", panoramas=True)
