"""The `cameras` stage: every later stage reads one camera format, a COLMAP text model, and one
folder of images beside it, ``images/``, one per camera named as the camera's image.

A pinhole camera's image is the capture's file itself, hard-linked (copied across file systems)
after it is checked: the size its camera says, finite pixels. PNG and JPEG stay sRGB-encoded as
the user gave them: scene/capture.read_view, which every stage reads them through, decodes them to
linear, so a linear EXR copy would cost four times the disk and a full decode-encode per image and
add nothing. A panorama (EQUIRECTANGULAR) becomes six cube-face PINHOLE cameras whose images are
resampled from it in linear RGB and written as float EXR (cameras/panorama.py).
"""

from __future__ import annotations

import logging
import math
import os
import shutil
from dataclasses import replace
from pathlib import Path, PurePosixPath

import numpy as np
from tqdm import tqdm

from ..scene.atomic import atomic_dir, check_output
from ..scene.cameras import (
    PANORAMA_MODEL,
    is_colmap_model,
    read_cameras,
    write_colmap,
    write_colmap_text,
)
from ..scene.capture import read_view
from ..scene.images import read_image, write_exr
from ..scene.types import Camera, SceneError, require_positive
from .panorama import face_cameras, unwrap

log = logging.getLogger(__name__)


def run(source, out_dir, images_dir=None, face_size: int | None = None, progress: bool = True) -> list[Camera]:
    """A capture's cameras (COLMAP model directory, text or binary, or a transforms.json), read by
    ``read_cameras`` and written to ``out_dir`` as a COLMAP text model (atomically). With
    ``images_dir`` (the capture's images: COLMAP's image names are relative to it), also
    ``out_dir/images/``: every pinhole image checked and linked, every panorama unwrapped into
    six faces of ``face_size`` pixels (default: a quarter of its width). Without it, the model
    only, and panoramas are refused. Returns the cameras written."""
    check_output(out_dir, "cameras")
    source = Path(source)
    if face_size is not None:
        face_size = require_positive("cameras --face-size", "cube-face width in pixels", face_size)
    cameras = read_cameras(source, panoramas=images_dir is not None)
    if not cameras:
        raise SceneError(source, "(cameras)", "at least one posed camera")
    if images_dir is None:
        write_colmap(out_dir, cameras)
        log.info("%s: %d camera(s) -> %s", source, len(cameras), out_dir)
        return cameras
    views = _locate(source, Path(images_dir), cameras)
    written = _plan(source, views, face_size)
    with atomic_dir(out_dir, kind="cameras") as tmp:
        images_out = tmp / "images"
        for camera, folder in tqdm(views, desc="cameras", unit="image", disable=not progress, leave=False):
            image = read_view(folder, camera)  # checked: there, its camera's size, finite
            if camera.model == PANORAMA_MODEL:
                for face, face_image in unwrap(image, camera, face_size):
                    write_exr(_inside(images_out, face.name), face_image)
            else:
                _link(folder / camera.name, _inside(images_out, camera.name))
        write_colmap_text(tmp, written)
    panoramas = sum(camera.model == PANORAMA_MODEL for camera, _ in views)
    log.info(
        "%s: %d camera(s) (%d panorama(s) unwrapped into 6 faces each) with images from %s -> %s",
        source,
        len(written),
        panoramas,
        images_dir,
        out_dir,
    )
    return written


def _locate(source: Path, images_dir: Path, cameras: list[Camera]) -> list[tuple[Camera, Path]]:
    """Each camera with the folder its image name is relative to. A COLMAP model's names are
    relative to the images folder; a transforms.json's file_path to the file's folder, so its
    cameras are renamed relative to the images folder when their image lies in it (the name every
    later stage looks for in cameras/images)."""
    if not images_dir.is_dir():
        raise SceneError(images_dir, "(directory)", "the folder of the capture's images")
    if is_colmap_model(source):
        views = [(camera, images_dir) for camera in cameras]
    else:  # read_cameras read a transforms.json: the file, or the one in the folder
        base = source.parent if source.is_file() else source
        views = [_relative_to_images(camera, base, images_dir) for camera in cameras]
    for camera, _ in views:
        name = PurePosixPath(camera.name)
        if name.is_absolute() or ".." in name.parts:
            raise SceneError(source, f"camera {camera.name} image name", "a relative path without '..'")
    return views


def _relative_to_images(camera: Camera, base: Path, images_dir: Path) -> tuple[Camera, Path]:
    try:
        inside = (base / camera.name).resolve().relative_to(images_dir.resolve())
    except ValueError:
        return camera, base
    return replace(camera, name=inside.as_posix()), images_dir


def _plan(source: Path, views: list[tuple[Camera, Path]], size: int | None) -> list[Camera]:
    """The cameras the stage writes (a panorama's six faces in its place), refused before any
    work if two share an image name."""
    written = []
    for camera, _ in views:
        if camera.model == PANORAMA_MODEL:
            written += face_cameras(camera, size)
        else:
            written.append(camera)
    seen = set()
    for camera in written:
        if camera.name in seen:
            raise SceneError(
                source, f"camera {camera.name} image name", "one camera per image name (a panorama's faces included)"
            )
        seen.add(camera.name)
    return written


def _inside(folder: Path, name: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def _link(source: Path, target: Path) -> None:
    """A hard link (no copy of a large image), or a copy where the file system refuses one
    (across file systems, or without hard links)."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def photograph_camera(photo, field_of_view: float | None = None, focal_length: float | None = None) -> Camera:
    """The camera of a photograph without a model: a pinhole at the world's origin looking down +z
    (OpenCV axes), its principal point the image's centre, its focal length given in pixels or
    by the horizontal field of view in degrees."""
    photo = Path(photo)
    height, width = read_image(photo).shape[:2]
    if (field_of_view is None) == (focal_length is None):
        raise SceneError(photo, "field of view", "one of field_of_view (degrees) or focal_length (pixels)")
    if focal_length is None:
        if not 0 < field_of_view < 180:
            raise SceneError(photo, "field_of_view", f"degrees in (0, 180), got {field_of_view}")
        focal_length = width / 2 / math.tan(math.radians(field_of_view) / 2)
    if not (math.isfinite(focal_length) and focal_length > 0):
        raise SceneError(photo, "focal_length", f"a positive number of pixels, got {focal_length}")
    params = np.array([focal_length, focal_length, width / 2, height / 2], np.float64)
    return Camera(photo.name, "PINHOLE", width, height, params, np.eye(3), np.zeros(3))


def run_photograph(photo, out_dir, field_of_view=None, focal_length=None) -> list[Camera]:
    """A one-camera COLMAP text model for a photograph (``photograph_camera``), the photograph
    linked into out_dir/images/."""
    check_output(out_dir, "cameras")
    camera = photograph_camera(photo, field_of_view, focal_length)
    with atomic_dir(out_dir, kind="cameras") as tmp:
        read_view(Path(photo).parent, camera)  # checked: finite pixels
        _link(Path(photo), _inside(tmp / "images", camera.name))
        write_colmap_text(tmp, [camera])
    log.info("%s: a camera of focal length %.1f px -> %s", photo, camera.focal[0], out_dir)
    return [camera]
