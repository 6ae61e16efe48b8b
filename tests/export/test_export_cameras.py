"""A UsdGeom.Camera made from a COLMAP camera projects points to the COLMAP camera's pixels.

The reference is pxr's own Gf.Camera (the frustum USD tools derive from the camera prim) against
scene/cameras.project_points (COLMAP's model): two independent implementations."""

import logging

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom

from invrender.export.cameras import author_camera, lens_of, read_camera
from invrender.scene.cameras import project_points
from invrender.scene.types import Camera
from invrender.synthesize.room import look_at


def _camera(model, params, width=120, height=80, eye=(0.3, 1.2, 2.0), target=(-0.2, 0.9, -1.0)):
    R, t = look_at(eye, target)
    return Camera("view.exr", model, width, height, np.asarray(params, np.float64), R, t)


CAMERAS = {
    "pinhole off centre, fx != fy": _camera("PINHOLE", [95.0, 131.5, 47.3, 44.9]),
    "simple pinhole": _camera("SIMPLE_PINHOLE", [70.0, 61.0, 38.5], width=123, height=77),
    "opencv": _camera("OPENCV", [88.0, 90.0, 60.5, 39.5, -0.12, 0.03, 0.001, -0.002]),
}


def _usd_camera(camera):
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    usd = author_camera(stage, "/camera", camera, (0.01, 100.0))
    return stage, usd


def _project_with_gf(usd: UsdGeom.Camera, points, width, height):
    """Pixels through Gf.Camera's frustum: world -> NDC -> pixel (v down, the film's edges are the
    image's edges)."""
    frustum = usd.GetCamera(Usd.TimeCode.Default()).frustum
    matrix = frustum.ComputeViewMatrix() * frustum.ComputeProjectionMatrix()
    ndc = np.array([matrix.Transform(Gf.Vec3d(*map(float, p))) for p in points])
    return np.stack([(ndc[:, 0] + 1) / 2 * width, (1 - ndc[:, 1]) / 2 * height], axis=1)


def _points_in_view(camera, n=200, seed=0):
    rng = np.random.default_rng(seed)
    pixels = rng.uniform([2, 2], [camera.width - 2, camera.height - 2], (n, 2))
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    depth = rng.uniform(0.3, 8.0, n)
    local = np.stack([(pixels[:, 0] - cx) / fx * depth, (pixels[:, 1] - cy) / fy * depth, depth], axis=1)
    return (local - camera.t) @ camera.R  # camera -> world: R^T (x - t)


@pytest.mark.parametrize("name", ["pinhole off centre, fx != fy", "simple pinhole"])
def test_usd_camera_projects_like_colmap_to_a_hundredth_of_a_pixel(name):
    camera = CAMERAS[name]
    _, usd = _usd_camera(camera)
    points = _points_in_view(camera)
    ours = _project_with_gf(usd, points, camera.width, camera.height)
    colmap = project_points(camera, points)
    error = np.abs(ours - colmap).max()
    assert error < 0.01, error
    corners = np.array([[0, 0], [camera.width, camera.height]], float)  # the film edges are the image edges
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    rays = np.stack([(corners[:, 0] - cx) / fx, (corners[:, 1] - cy) / fy, np.ones(2)], axis=1) * 3.0
    assert (
        np.abs(_project_with_gf(usd, (rays - camera.t) @ camera.R, camera.width, camera.height) - corners).max() < 0.01
    )


def test_opencv_camera_exports_its_pinhole_part_with_a_warning(caplog):
    camera = CAMERAS["opencv"]
    with caplog.at_level(logging.WARNING):
        _, usd = _usd_camera(camera)
    assert "distortion" in caplog.text and "pinhole part" in caplog.text
    points = _points_in_view(camera)
    pinhole = Camera(camera.name, "PINHOLE", camera.width, camera.height, camera.params[:4], camera.R, camera.t)
    assert (
        np.abs(_project_with_gf(usd, points, camera.width, camera.height) - project_points(pinhole, points)).max()
        < 0.01
    )
    # ... while the distorted projection is what it is not: the check above can fail
    assert (
        np.abs(_project_with_gf(usd, points, camera.width, camera.height) - project_points(camera, points)).max() > 0.5
    )


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_camera_comes_back_exactly(name):
    camera = CAMERAS[name]
    stage, usd = _usd_camera(camera)
    back = read_camera(usd.GetPrim(), np.eye(4), None, "test")
    assert back.name == camera.name and back.model == camera.model
    assert (back.width, back.height) == (camera.width, camera.height)
    for field in ("params", "R", "t"):
        assert np.array_equal(getattr(back, field), getattr(camera, field)), field


def test_an_edited_lens_and_pose_win_over_the_stored_camera():
    camera = CAMERAS["opencv"]
    stage, usd = _usd_camera(camera)
    usd.GetFocalLengthAttr().Set(lens_of(camera).focal * 2)
    op = UsdGeom.Xformable(usd).GetOrderedXformOps()[0]
    op.Set(op.Get() * Gf.Matrix4d().SetTranslate(Gf.Vec3d(0.5, 0, 0)))  # 0.5 m along world +X
    back = read_camera(usd.GetPrim(), np.eye(4), None, "test")
    assert back.model == "OPENCV" and np.allclose(back.params[4:], camera.params[4:])  # distortion kept
    assert np.allclose(back.focal, 2 * np.asarray(camera.focal), rtol=1e-6)
    assert np.allclose(back.principal_point, camera.principal_point, atol=1e-4)
    assert np.allclose(back.center, camera.center + [0.5, 0, 0], atol=1e-12)
    assert np.allclose(back.R, camera.R, atol=1e-12)


def test_standard_only_reads_a_pinhole_from_the_lens():
    camera = CAMERAS["pinhole off centre, fx != fy"]
    stage, usd = _usd_camera(camera)
    back = read_camera(usd.GetPrim(), np.eye(4), (camera.width, camera.height), "test", exact=False)
    assert back.model == "PINHOLE"
    assert np.allclose(back.params, camera.params, rtol=1e-6, atol=1e-4)
    assert np.allclose(back.R, camera.R, atol=1e-12) and np.allclose(back.t, camera.t, atol=1e-12)
