"""Copies of a printed square seen from one camera, each drawn by its exact homography: the
photograph a few duplicates tests need where the print's true position is known to the pixel."""

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.spatial.transform import Rotation

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


def printed_scene():
    """(poses {id: T_cam_from_obj}, grey photograph, instance ids) of three copies of one print."""
    texture = gaussian_filter(np.random.default_rng(7).random((TEXELS, TEXELS)), 2.0)
    texture = (texture - texture.min()) / np.ptp(texture)  # print-like detail, 0..1
    poses = {1: pose(-25, 0, -0.16), 2: pose(5, 70, 0.0), 3: pose(30, 200, 0.16)}
    gray, ids = draw(texture, poses)
    return poses, gray, ids
