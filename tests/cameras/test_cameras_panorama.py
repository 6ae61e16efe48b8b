"""Equirectangular panoramas become six cube-face pinhole views (MILO takes a 360 camera's rooms
in this way). Checked against two references that share no code with the unwrapping:

- analytic: a panorama whose every pixel is a known function of its ray's direction (RGB = the
  world direction mapped to [0, 1]), the directions from pycolmap's EQUIRECTANGULAR model (a COLMAP
  capture) or from nerfstudio's ray formula (a transforms.json capture); each face pixel must be
  the function at the direction of that pixel's ray, as the face camera projects it;
- the renderer: a panorama of a sky (kg is a function of direction alone), unwrapped, against the
  renderer's own pinhole renders of that sky from the face cameras.
"""

import json

import cv2
import numpy as np
import pycolmap
import pytest

from invrender.cli import main
from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.scene.cameras import pixel_directions, project_points, read_cameras
from invrender.scene.cubemap import lookup_cube, texel_directions
from invrender.scene.images import read_image, write_exr
from invrender.scene.types import Maps, Mesh, Scene

WIDTH, HEIGHT = 256, 128
CENTER = np.array([0.4, 1.3, -0.2])
# A tilted panorama: its faces are not the world's axes, so a mix-up of rotations shows.
R_PANO = cv2.Rodrigues(np.array([0.3, -1.1, 0.2]))[0]  # world-to-camera


def colmap_directions():
    """World direction of each panorama pixel centre, by pycolmap's EQUIRECTANGULAR model."""
    camera = pycolmap.Camera(camera_id=1, model="EQUIRECTANGULAR", width=WIDTH, height=HEIGHT, params=[WIDTH, HEIGHT])
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    d_cam = camera.cam_ray_from_img(np.stack([xs.ravel(), ys.ravel()], axis=1))
    return (d_cam @ R_PANO).reshape(HEIGHT, WIDTH, 3)


def c2w_opengl():
    c2w = np.eye(4)
    c2w[:3, :3] = R_PANO.T @ np.diag([1.0, -1.0, -1.0])  # OpenCV camera axes -> OpenGL's
    c2w[:3, 3] = CENTER
    return c2w


def nerfstudio_directions():
    """World direction of each panorama pixel centre by nerfstudio's EQUIRECTANGULAR rays
    (cameras.py: fx = W / 2, fy = H, principal point at the centre; OpenGL camera axes)."""
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    coord_x = (xs - WIDTH / 2) / (WIDTH / 2)
    coord_y = -(ys - HEIGHT / 2) / HEIGHT  # "switch from OpenCV to OpenGL"
    theta, phi = -np.pi * coord_x, np.pi * (0.5 - coord_y)
    d_gl = np.stack([-np.sin(theta) * np.sin(phi), np.cos(phi), -np.cos(theta) * np.sin(phi)], axis=-1)
    return d_gl @ c2w_opengl()[:3, :3].T


def write_colmap_capture(folder, image):
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="EQUIRECTANGULAR", width=WIDTH, height=HEIGHT, params=[WIDTH, HEIGHT])
    )
    pose = pycolmap.Rigid3d(np.hstack([R_PANO, (-R_PANO @ CENTER)[:, None]]))
    rec.add_image_with_trivial_frame(pycolmap.Image(name="room.exr", camera_id=1, image_id=1), pose)
    (folder / "sparse").mkdir(parents=True)
    rec.write_text(str(folder / "sparse"))
    write_exr(folder / "images" / "room.exr", image)
    return folder / "sparse"


def write_transforms_capture(folder, image):
    doc = {
        "camera_model": "EQUIRECTANGULAR",
        "w": WIDTH,
        "h": HEIGHT,
        "frames": [{"file_path": "images/room.exr", "transform_matrix": c2w_opengl().tolist()}],
    }
    (folder / "images").mkdir(parents=True)
    (folder / "transforms.json").write_text(json.dumps(doc))
    write_exr(folder / "images" / "room.exr", image)
    return folder / "transforms.json"


def unwrap_cli(source, folder, *more):
    out = folder / "cameras"
    assert main(["cameras", str(source), "--out", str(out), "--images", str(folder / "images"), *more]) == 0
    return read_cameras(out), out / "images"


def face_rays(camera):
    """Unit world direction of each pixel centre of a face camera, checked to project back onto
    that pixel centre (scene/cameras' projection is the convention)."""
    d = pixel_directions(camera)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    ys, xs = np.mgrid[0 : camera.height, 0 : camera.width] + 0.5
    back = project_points(camera, camera.center + d.reshape(-1, 3)).reshape(camera.height, camera.width, 2)
    np.testing.assert_allclose(back, np.stack([xs, ys], -1), atol=1e-9)
    return d


@pytest.mark.parametrize(
    "write, directions, size",
    [(write_colmap_capture, colmap_directions, 41), (write_transforms_capture, nerfstudio_directions, None)],
    ids=["colmap", "transforms.json"],
)
def test_each_face_pixel_is_the_panorama_at_its_ray_direction(tmp_path, write, directions, size):
    panorama = (0.5 * (directions() + 1.0)).astype(np.float32)  # RGB = direction in [0, 1]
    source = write(tmp_path, panorama)
    cameras, images = unwrap_cli(source, tmp_path, *(["--face-size", str(size)] if size else []))
    assert [c.name for c in cameras] == [f"room_{f}.exr" for f in ("nx", "ny", "nz", "px", "py", "pz")]
    size = size or WIDTH // 4
    errors = []
    for camera in cameras:
        assert camera.model == "PINHOLE" and (camera.width, camera.height) == (size, size)
        np.testing.assert_allclose(camera.center, CENTER, atol=1e-12)
        face = read_image(images / camera.name)
        errors.append(np.abs(face - 0.5 * (face_rays(camera) + 1.0)))
    errors = np.stack(errors)
    # bilinear interpolation of a function whose slope is 1/2 per radian on 1.4-degree pixels
    # (cv2.remap rounds coordinates to 1/32 pixel): measured 7e-5; a face turned or mirrored is
    # 0.1 off, and reading beyond a pole in the same column (not across the pole) 5e-3 (an odd
    # face size puts a pixel centre on each pole)
    assert errors.max() < 2e-4, errors.max()
    # together the faces see the whole sphere: each of a cube map's texel directions in one face
    rays = np.concatenate([face_rays(c).reshape(-1, 3) for c in cameras])
    nearest = (texel_directions(8).reshape(-1, 3) @ rays.T).max(axis=1)
    assert nearest.min() > np.cos(np.radians(90 / size * 1.5))


def test_a_panorama_of_a_sky_unwraps_into_the_renders_of_the_sky_from_the_face_cameras(tmp_path):
    maps = Maps.uniform(size=(2, 2), kg=0.0, cube=64)
    maps.kg[:] = 0.2 + 1.5 * (0.5 + 0.5 * texel_directions(64)) ** 2  # smooth, coloured, not symmetric
    source = write_colmap_capture(tmp_path, lookup_cube(maps.kg, colmap_directions()).astype(np.float32))
    cameras, images = unwrap_cli(source, tmp_path, "--face-size", "24")
    far_triangle = Mesh(
        np.array([[1e4, 1e4, 1e4], [1e4 + 1, 1e4, 1e4], [1e4, 1e4 + 1, 1e4]], np.float32),
        np.array([[0, 1, 2]], np.int32),
        np.zeros((3, 2), np.float32),
    )
    features = Features.only(max_bounces=0, environment=True)
    renderer = Renderer(Scene(far_triangle, maps, cameras), features)
    for camera in cameras:
        rendered = renderer.render(camera, spp=16, seed=0)["radiance"]
        unwrapped = read_image(images / camera.name)
        error = np.abs(unwrapped - rendered)
        # both are nearest-texel reads of a 64-texel sky, one through a 256-pixel panorama and
        # bilinear, one box-filtered over the pixel: measured mean 0.004, max 0.024 (a texel's
        # step is ~0.04); a mirrored face is off by the sky's range, ~1 (measured 0.63)
        assert error.mean() < 0.006 and error.max() < 0.04, (camera.name, error.mean(), error.max())


def test_a_face_named_like_a_photograph_or_a_face_size_of_zero_is_refused(tmp_path, capsys):
    source = write_colmap_capture(tmp_path, np.ones((HEIGHT, WIDTH, 3), np.float32))
    out = tmp_path / "cameras"
    cli = ["cameras", str(source), "--out", str(out), "--images", str(tmp_path / "images")]
    assert main([*cli, "--face-size", "0"]) == 2
    assert (
        "cameras --face-size: cube-face width in pixels: expected an integer of at least 1, got 0"
        in capsys.readouterr().err
    )
    rec = pycolmap.Reconstruction(str(source))  # a photograph named as the panorama's +x face
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=2, model="PINHOLE", width=4, height=4, params=[2, 2, 2, 2])
    )
    rec.add_image_with_trivial_frame(pycolmap.Image(name="room_px.exr", camera_id=2, image_id=2), pycolmap.Rigid3d())
    rec.write_text(str(source))
    write_exr(tmp_path / "images" / "room_px.exr", np.ones((4, 4, 3), np.float32))
    assert main(cli) == 2
    assert "camera room_px.exr image name: expected one camera per image name" in capsys.readouterr().err
    assert not out.exists()
