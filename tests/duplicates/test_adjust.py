"""adjust.py: the sub-pixel shift of a patch against a known shift, the planar flip against the
projection it must keep, and its choice by the mask against a cube's true pose."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from scipy.spatial.transform import Rotation

from invrender.duplicates import adjust

K = np.array([[1400.0, 0, 800], [0, 1400.0, 600], [0, 0, 1]])


def project(R, t, X):
    cam = X @ R.T + t
    return cam[:, :2] / cam[:, 2:] * np.diag(K)[:2] + K[:2, 2]


@pytest.fixture(scope="module")
def texture():
    rng = np.random.default_rng(3)
    return gaussian_filter(rng.random((200, 200)), 1.5)  # print-like detail at a few pixels


def test_patch_shifts_recover_a_known_subpixel_shift(texture):
    grid = np.stack(np.meshgrid(np.arange(-7, 8), np.arange(-7, 8)), -1).reshape(-1, 2).astype(float)
    centres = np.array([[60.5, 70.5], [120.25, 90.75], [140.5, 140.5]])
    true = np.array([[0.37, -0.62], [-1.21, 0.44], [0.9, 1.3]])
    refs = centres[:, None] + grid
    # the target patch starts where the shift is unknown: at the reference's pixels moved by it
    # the other way, so the shift found must be the true one
    targets = refs - true[:, None]
    shift, ncc = adjust.patch_shifts(texture, refs, targets, adjust.ITERATIONS)
    np.testing.assert_allclose(shift, true, atol=0.03)
    assert ncc.min() > 0.99


def test_the_flip_projects_a_plane_the_same_at_another_rotation():
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(-0.05, 0.05, (200, 2)), np.zeros(200)]  # a 10 cm face, object frame
    R = Rotation.from_euler("xyz", [35, -20, 50], degrees=True).as_matrix()
    t = np.array([0.2, -0.1, 1.5])
    R2, t2 = adjust._flipped(R, t, np.array([0, 0, 1.0]), plane.mean(axis=0))
    angle = np.degrees(Rotation.from_matrix(R2 @ R.T).magnitude())
    moved = np.linalg.norm(project(R2, t2, plane) - project(R, t, plane), axis=1)
    assert np.isclose(np.linalg.det(R2), 1.0)
    assert angle > 30  # twice the face's tilt to the line of sight, about
    assert moved.max() < 0.1 * np.linalg.norm(project(R, t, plane) - project(R, t, plane).mean(0), axis=1).max()


def test_the_mask_tells_the_true_pose_of_a_cube_from_its_flip():
    corners = np.array(np.meshgrid([-0.05, 0.05], [-0.03, 0.03], [-0.02, 0.02])).reshape(3, -1).T
    faces = [corners[corners[:, 2] > 0]]  # the face the copy shows
    R = Rotation.from_euler("xyz", [30, 25, 10], degrees=True).as_matrix()
    t = np.array([0.1, 0.05, 1.2])
    import cv2

    mask = np.zeros((1200, 1600), np.uint8)
    cv2.fillConvexPoly(mask, cv2.convexHull(np.round(project(R, t, corners) - 0.5).astype(np.int32)), 1)
    R2, t2 = adjust._flipped(R, t, np.array([0, 0, 1.0]), faces[0].mean(axis=0))
    true_iou = adjust._silhouette_iou(corners, R, t, K, mask > 0)
    flip_iou = adjust._silhouette_iou(corners, R2, t2, K, mask > 0)
    assert true_iou > 0.95
    assert flip_iou < true_iou - adjust.FLIP_IOU_GAIN
