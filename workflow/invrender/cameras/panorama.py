"""Equirectangular panoramas unwrapped into six cube-face pinhole views (MILO section 4: a 360
camera's panoramas are taken in "with cubic projection to prevent gradient explosion near the
poles"): each face pixel reads the panorama bilinearly (cv2.remap) at its ray's direction."""

from __future__ import annotations

from pathlib import PurePosixPath

import cv2
import numpy as np

from ..scene.cameras import cube_face_cameras, panorama_pixels, pixel_directions
from ..scene.types import Camera


def face_cameras(panorama: Camera, size: int | None = None) -> list[Camera]:
    """The six cube-face cameras of ``panorama``: at its centre, turned with it (scene/cameras'
    ``cube_face_cameras``), named ``<panorama's name without suffix>_<face>.exr``, ``size``
    pixels wide and high, by default a quarter of the panorama's width, which keeps the equator's
    sampling (each face spans 90 of the 360 degrees)."""
    size = size if size is not None else max(1, round(panorama.width / 4))
    stem = str(PurePosixPath(panorama.name).with_suffix(""))
    return cube_face_cameras(panorama.center, size, stem, rotation=panorama.R)


def _pole_padded(image: np.ndarray) -> np.ndarray:
    """The panorama with one pixel more on every side, so that bilinear reads near its edges are
    reads of the sphere: the columns wrap around in longitude; the row beyond a pole is the
    first (last) row seen across the pole, i.e. at the opposite longitude (half a turn away,
    the mean of the two nearest columns for an odd width)."""
    width = image.shape[1]
    half = width // 2

    def across(row):
        turned = np.roll(row, -half, axis=0)
        return turned if width % 2 == 0 else 0.5 * (turned + np.roll(row, -half - 1, axis=0))

    rows = np.concatenate([across(image[0])[None], image, across(image[-1])[None]], axis=0)
    return np.ascontiguousarray(np.concatenate([rows[:, -1:], rows, rows[:, :1]], axis=1), np.float32)


def unwrap(image: np.ndarray, panorama: Camera, size: int | None = None) -> list[tuple[Camera, np.ndarray]]:
    """The six cube-face cameras of ``panorama`` (``face_cameras``), each with its (size, size, 3)
    float32 image resampled from the linear equirectangular ``image``."""
    padded = _pole_padded(np.asarray(image, np.float32))
    faces = []
    for face in face_cameras(panorama, size):
        d_panorama = pixel_directions(face) @ np.asarray(panorama.R, np.float64).T  # world -> panorama axes
        u, v = np.moveaxis(panorama_pixels(d_panorama, panorama.width, panorama.height), -1, 0)
        # remap's coordinates count pixel centres from 0; the padding shifts them by one
        map_x, map_y = (u + 0.5).astype(np.float32), (v + 0.5).astype(np.float32)
        resampled = cv2.remap(padded, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        faces.append((face, resampled.reshape(face.height, face.width, -1)))
    return faces
