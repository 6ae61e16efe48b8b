"""photo.py: where the copies' pixels agree. Three copies of a printed square seen from one camera
(each drawn by its exact homography), the square's mesh standing 2 mm off it along its normal:
the points found lie on the print, not on the mesh."""

import cv2
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from scipy.spatial.transform import Rotation

from invrender.duplicates import photo
from invrender.scene.types import Mesh

K = np.array([[1400.0, 0, 800], [0, 1400.0, 600], [0, 0, 1]])
SIZE = (1600, 1200)
HALF = 0.05  # the square: [-5, 5] cm in x and y of its frame, z = 0
TEXELS = 400


def pose(tilt_deg, spin_deg, x) -> np.ndarray:
    """T_cam_from_obj: the square's +z towards the camera, tilted and turned in its plane."""
    R = Rotation.from_euler("y", tilt_deg, degrees=True) * Rotation.from_euler("x", 180, degrees=True)
    R = R * Rotation.from_euler("z", spin_deg, degrees=True)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R.as_matrix(), [x, 0.0, 0.5]
    return T


def draw(texture, poses):
    """The grey photograph and its instance ids: each copy is its texture under the homography
    K [r1 r2 t] from the square's plane, after texel -> plane coordinates."""
    gray, ids = np.zeros(SIZE[::-1], np.float32), np.zeros(SIZE[::-1], np.int32)
    texel = 2 * HALF / TEXELS
    to_plane = np.array([[texel, 0, -HALF + texel / 2], [0, texel, -HALF + texel / 2], [0, 0, 1]])
    # COLMAP's pixel centres: pixel x covers [x, x + 1), OpenCV's centre is at x
    to_opencv = np.array([[1, 0, -0.5], [0, 1, -0.5], [0, 0, 1]])
    for i, T in poses.items():
        H = to_opencv @ K @ np.c_[T[:3, :2], T[:3, 3]] @ to_plane
        drawn = cv2.warpPerspective(texture.astype(np.float32), H, SIZE, flags=cv2.INTER_LINEAR)
        inside = cv2.warpPerspective(np.ones_like(texture, np.float32), H, SIZE, flags=cv2.INTER_NEAREST) > 0.5
        gray[inside], ids[inside] = drawn[inside], i
    return gray, ids


def square_mesh(z: float, n: int = 11) -> Mesh:
    a = np.linspace(-0.8 * HALF, 0.8 * HALF, n)
    x, y = np.meshgrid(a, a)
    positions = np.c_[x.ravel(), y.ravel(), np.full(n * n, z)]
    k = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    faces = np.r_[np.c_[k, k + 1, k + n + 1], np.c_[k, k + n + 1, k + n]]  # counter-clockwise from +z
    return Mesh(positions=positions.astype(np.float32), faces=faces.astype(np.int32), uvs=None)


@pytest.fixture(scope="module")
def scene():
    texture = gaussian_filter(np.random.default_rng(7).random((TEXELS, TEXELS)), 2.0)
    texture = (texture - texture.min()) / np.ptp(texture)  # print-like detail, 0..1
    poses = {1: pose(-25, 0, -0.16), 2: pose(5, 70, 0.0), 3: pose(30, 200, 0.16)}
    gray, ids = draw(texture, poses)
    return poses, gray, ids


def test_the_points_lie_on_the_print_not_on_the_mesh_standing_off_it(scene):
    poses, gray, ids = scene
    points, report = photo.consistent_points(square_mesh(0.002), poses, K, gray, ids)
    assert report.kept > 0.8 * report.vertices and report.score_median > 0.9, report
    # the mesh is 2 mm off; the points within a fiftieth of a pixel (0.36 mm here) of the print
    # (measured 7 um median, 16 um p90)
    assert np.median(np.abs(points[:, 2])) < 3e-5 and np.percentile(np.abs(points[:, 2]), 90) < 5e-5


def test_a_plain_face_gives_no_point(scene):
    poses, _, ids = scene
    flat = np.where(ids > 0, 0.5, 0.0).astype(np.float32)  # no texture: any offset agrees
    points, report = photo.consistent_points(square_mesh(0.002), poses, K, flat, ids)
    assert len(points) == 0 and report.tried == 0
