"""Cameras: COLMAP sparse models (text or binary) and nerfstudio / instant-ngp transforms.json.

Everything becomes ``types.Camera``: world-to-camera ``x_cam = R x_world + t``, OpenCV axes
(x right, y down, z forward), pixel (0, 0)'s centre at (0.5, 0.5), COLMAP parameter order.
Lists are sorted by image name.

transforms.json convention (nerfstudio, instant-ngp, NeRF's Blender scenes): each frame's
``transform_matrix`` is camera-to-world with OpenGL camera axes (x right, y up, z backwards);
intrinsics ``fl_x, fl_y, cx, cy, w, h`` (pixels), ``k1, k2, p1, p2`` and ``camera_model`` are read
from the frame, else from the top level; ``camera_angle_x`` / ``camera_angle_y`` (radians, full
field of view) stand in for missing focal lengths; a missing ``w, h`` is read from the image.
The world frame is the file's: no axis change is applied to it.

Panoramas (``read_cameras(..., panoramas=True)``, for the cameras stage only): a COLMAP camera of
model ``EQUIRECTANGULAR`` (params ``w, h``), or a transforms.json ``camera_model`` of
``EQUIRECTANGULAR`` (nerfstudio's camera type), become a ``Camera`` of that model, params
``[w, h]``. Both describe the same full sphere in OpenCV camera axes: the image's centre looks
along +z, columns turn right (+x), the top row is up (-y); ``panorama_pixels`` is the projection.
No other stage takes them: the cameras stage unwraps each into six cube-face PINHOLE views.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from .atomic import atomic_dir
from .types import Camera, SceneError

__all__ = [
    "read_cameras",
    "read_colmap",
    "read_transforms_json",
    "write_colmap",
    "write_colmap_text",
    "check_camera",
    "is_colmap_model",
    "check_panorama",
    "project_points",
    "pixel_directions",
    "panorama_pixels",
    "cube_face_cameras",
    "PANORAMA_MODEL",
    "look_at",
    "pinhole_camera",
]

log = logging.getLogger(__name__)

SUPPORTED_MODELS = ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV")
PARAM_COUNT = {"PINHOLE": 4, "SIMPLE_PINHOLE": 3, "OPENCV": 8}
# A 360 x 180 degree panorama: COLMAP's model name, which nerfstudio's transforms.json uses too.
PANORAMA_MODEL = "EQUIRECTANGULAR"
PANORAMA_HINT = f"({PANORAMA_MODEL} panoramas: `invrender cameras --images` unwraps them into cube-face views)"
# OpenGL camera axes -> OpenCV camera axes (flip y and z), as a right factor on camera-to-world.
GL_TO_CV = np.diag([1.0, -1.0, -1.0])


def read_cameras(path, panoramas: bool = False) -> list[Camera]:
    """Read a COLMAP sparse model directory or a transforms.json file.

    A directory without COLMAP files but with a ``transforms.json`` is read as the latter.
    ``panoramas``: take EQUIRECTANGULAR cameras too (the cameras stage, which unwraps them);
    otherwise they are refused.
    """
    path = Path(path)
    if path.is_file():
        if path.suffix.lower() == ".json":
            return read_transforms_json(path, panoramas)
        raise SceneError(path, "(file)", "a COLMAP sparse model directory or a transforms.json file")
    if not path.is_dir():
        raise SceneError(path, "(file)", "an existing COLMAP sparse model directory or transforms.json")
    if not is_colmap_model(path) and (path / "transforms.json").is_file():
        return read_transforms_json(path / "transforms.json", panoramas)
    return read_colmap(path, panoramas)


# ---------------------------------------------------------------------------- COLMAP


def is_colmap_model(path) -> bool:
    """A directory with COLMAP model files (text or binary): read_cameras reads it as COLMAP even
    when a transforms.json lies beside them."""
    path = Path(path)
    return path.is_dir() and any((path / f"{n}.{e}").exists() for n in ("cameras", "images") for e in ("txt", "bin"))


def _model_file(directory: Path, name: str) -> Path:
    for ext in ("bin", "txt"):
        if (directory / f"{name}.{ext}").exists():
            return directory / f"{name}.{ext}"
    return directory / f"{name}.txt"


def read_colmap(directory, panoramas: bool = False) -> list[Camera]:
    import pycolmap

    directory = Path(directory)
    try:
        rec = pycolmap.Reconstruction(str(directory))
    except Exception as exc:  # pycolmap raises ValueError / IndexError with COLMAP's message
        raise _colmap_error(directory, exc) from None
    cameras_file = _model_file(directory, "cameras")
    out = []
    skipped = []
    for image in sorted(rec.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            skipped.append(image.name)
            continue
        cam = rec.cameras[image.camera_id]
        model = cam.model.name
        field = f"camera {image.camera_id} (image {image.name})"
        if model not in SUPPORTED_MODELS and not (panoramas and model == PANORAMA_MODEL):
            hint = f" {PANORAMA_HINT}" if model == PANORAMA_MODEL else ""
            raise SceneError(cameras_file, f"{field} model", f"one of {', '.join(SUPPORTED_MODELS)}, got {model}{hint}")
        pose = image.cam_from_world().matrix()
        camera = Camera(
            name=image.name,
            model=model,
            width=int(cam.width),
            height=int(cam.height),
            params=np.asarray(cam.params, np.float64).copy(),
            R=np.asarray(pose[:, :3], np.float64).copy(),
            t=np.asarray(pose[:, 3], np.float64).copy(),
        )
        (check_panorama if model == PANORAMA_MODEL else check_camera)(camera, cameras_file, field)
        out.append(camera)
    if skipped:
        log.warning("%s: %d image(s) without a pose skipped: %s", directory, len(skipped), ", ".join(skipped[:5]))
    return out


# How far outside the image the principal point may lie, as a fraction of the image's size: real
# lenses put it within a few percent of the centre; farther out is a unit or crop mistake.
PRINCIPAL_POINT_MARGIN = 0.25


def check_camera(cam: Camera, file, field: str | None = None) -> None:
    """Refuse a camera that cannot image anything: an unsupported model or parameter count, a
    size below 1 pixel, non-finite parameters, focal lengths that are not positive, a principal
    point more than PRINCIPAL_POINT_MARGIN of the image outside it, or a pose that is not a finite
    rigid transform (R orthonormal, det +1). ``field`` names the camera in the file (default:
    ``camera <name>``)."""
    field = field or f"camera {cam.name}"
    if cam.model not in SUPPORTED_MODELS:
        raise SceneError(file, f"{field} model", f"one of {', '.join(SUPPORTED_MODELS)}, got {cam.model}")
    params = np.asarray(cam.params, np.float64)
    if len(params) != PARAM_COUNT[cam.model]:
        raise SceneError(file, f"{field} params", f"{PARAM_COUNT[cam.model]} values for {cam.model}, got {len(params)}")
    if not (cam.width >= 1 and cam.height >= 1):
        raise SceneError(file, f"{field} width,height", f"at least 1 pixel each, got {cam.width} x {cam.height}")
    if not np.isfinite(params).all():
        raise SceneError(file, f"{field} params", f"finite numbers, got {params.tolist()}")
    (fx, fy), (cx, cy) = cam.focal, cam.principal_point
    if not (fx > 0 and fy > 0):
        raise SceneError(file, f"{field} focal length", f"positive focal lengths (pixels), got fx {fx:g}, fy {fy:g}")
    mx, my = PRINCIPAL_POINT_MARGIN * cam.width, PRINCIPAL_POINT_MARGIN * cam.height
    if not (-mx <= cx <= cam.width + mx and -my <= cy <= cam.height + my):
        raise SceneError(
            file,
            f"{field} principal point",
            f"cx, cy within the {cam.width} x {cam.height} image "
            f"or {PRINCIPAL_POINT_MARGIN:.0%} of its size outside it, got ({cx:g}, {cy:g})",
        )
    _check_pose(cam, file, field)


def check_panorama(cam: Camera, file, field: str | None = None) -> None:
    """Refuse a panorama that is not a full sphere (params w, h other than the image's size: a
    crop or a rescale, which the unwrapping does not model), or whose size or pose is not one a
    camera can have (as ``check_camera``)."""
    field = field or f"camera {cam.name}"
    if not (cam.width >= 1 and cam.height >= 1):
        raise SceneError(file, f"{field} width,height", f"at least 1 pixel each, got {cam.width} x {cam.height}")
    params = np.asarray(cam.params, np.float64)
    if params.shape != (2,) or not np.allclose(params, [cam.width, cam.height]):
        raise SceneError(
            file,
            f"{field} params",
            f"w, h equal to the {cam.width} x {cam.height} image (a full 360 x 180 degree panorama), "
            f"got {params.tolist()}",
        )
    _check_pose(cam, file, field)


def _check_pose(cam: Camera, file, field: str) -> None:
    R, t = np.asarray(cam.R, np.float64), np.asarray(cam.t, np.float64)
    if R.shape != (3, 3) or t.shape != (3,) or not (np.isfinite(R).all() and np.isfinite(t).all()):
        raise SceneError(file, f"{field} pose", "a finite rotation and translation")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise SceneError(
            file, f"{field} pose rotation", f"an orthonormal rotation with det +1, got det {np.linalg.det(R):.6g}"
        )


def _colmap_error(directory: Path, exc: Exception) -> SceneError:
    """COLMAP's failed check as a SceneError naming the model file it concerns and the field."""
    message = " ".join(str(exc).split())
    reason = message.split("] ", 1)[-1].replace("Check failed: ", "")
    lower = message.lower()
    if "verifyparams" in lower:
        return SceneError(
            _model_file(directory, "cameras"),
            "camera params",
            f"the parameter count and values of each camera's model ({reason})",
        )
    if "rig with id" in lower:
        return SceneError(
            _model_file(directory, "frames"),
            "frame rig_id",
            f"the id of a rig in {_model_file(directory, 'rigs').name} ({reason})",
        )
    # Which file a failed check concerns, by the words COLMAP's readers use for its fields.
    for name, words in (
        ("frames", ("rig with id", "frame", "rig_from_world", "data_id")),
        ("rigs", ("rig", "sensor")),
        ("cameras", ("camera",)),
        ("images", ("image",)),
        ("points3D", ("point",)),
    ):
        if any(w in lower for w in words):
            return SceneError(_model_file(directory, name), "(COLMAP model)", f"a readable {name} file ({reason})")
    return SceneError(directory, "(COLMAP model)", f"a readable COLMAP sparse model ({reason})")


def write_colmap(directory, cameras: list[Camera]) -> None:
    """Write a text COLMAP model (cameras, images, rigs, frames, empty points3D) atomically, as a
    directory of kind "cameras" (``write_colmap_text`` is the model's part)."""
    with atomic_dir(directory, kind="cameras") as tmp:
        write_colmap_text(tmp, cameras)


def write_colmap_text(directory, cameras: list[Camera]) -> None:
    """Write a text COLMAP model into the existing ``directory`` (not atomically: the caller's
    ``atomic_dir`` is). One COLMAP camera, trivial rig and trivial frame per image, ids 1..n in
    image-name order. pycolmap 4 also writes rigs.txt and frames.txt; COLMAP 3.x readers ignore
    them."""
    import pycolmap

    directory = Path(directory)
    cameras = sorted(cameras, key=lambda c: c.name)
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise SceneError(directory, f"camera {dup} name", "unique image names")
    rec = pycolmap.Reconstruction()
    for i, cam in enumerate(cameras, 1):
        check_camera(cam, directory)
        rec.add_camera_with_trivial_rig(
            pycolmap.Camera(
                camera_id=i,
                model=cam.model,
                width=int(cam.width),
                height=int(cam.height),
                params=np.asarray(cam.params, np.float64),
            )
        )
        pose = np.hstack([np.asarray(cam.R, np.float64), np.asarray(cam.t, np.float64).reshape(3, 1)])
        rec.add_image_with_trivial_frame(pycolmap.Image(name=cam.name, camera_id=i, image_id=i), pycolmap.Rigid3d(pose))
    rec.write_text(str(directory))


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera (R, t) of an OpenCV camera at ``eye`` looking at ``target``:
    z forward, x right, y down (so ``up`` appears upwards in the image)."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: the view direction is parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])  # rows: camera axes in world coordinates
    return R, -R @ eye


def pinhole_camera(name: str, eye, target, width: int, height: int, fov_deg: float) -> Camera:
    """A PINHOLE camera with square pixels, ``fov_deg`` horizontal field of view, centred
    principal point (pixel (0, 0)'s centre at (0.5, 0.5))."""
    f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    R, t = look_at(eye, target)
    params = np.array([f, f, width / 2, height / 2], np.float64)
    return Camera(name=name, model="PINHOLE", width=int(width), height=int(height), params=params, R=R, t=t)


def project_points(camera: Camera, points) -> np.ndarray:
    """Project (N, 3) world points to (N, 2) pixel coordinates (COLMAP convention, OPENCV distortion).

    Points behind the camera get NaN.
    """
    X = np.asarray(points, np.float64).reshape(-1, 3)
    xc = X @ np.asarray(camera.R, np.float64).T + np.asarray(camera.t, np.float64)
    z = xc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = xc[:, 0] / z, xc[:, 1] / z
    k1, k2, p1, p2 = camera.distortion
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    uv = np.stack([fx * xd + cx, fy * yd + cy], axis=1)
    uv[z <= 0] = np.nan
    return uv


def binned_camera(camera: Camera, factor: int) -> Camera:
    """The pinhole camera of an image ``factor`` times smaller by whole blocks of pixels (the
    right and bottom remainders cut), as ``images.block_mean`` reduces an image."""
    fx, fy, cx, cy = np.asarray(camera.params, np.float64)
    params = np.array([fx / factor, fy / factor, cx / factor, cy / factor])
    return Camera(camera.name, "PINHOLE", camera.width // factor, camera.height // factor, params, camera.R, camera.t)


def resized_camera(camera: Camera, width: int) -> Camera:
    """The pinhole camera with its image resized to ``width`` (height in proportion, rounded):
    the same view, intrinsics scaled per axis by the sizes' ratios."""
    height = max(1, round(camera.height * width / camera.width))
    sx, sy = width / camera.width, height / camera.height
    fx, fy, cx, cy = np.asarray(camera.params, np.float64)[:4]
    params = np.array([fx * sx, fy * sy, cx * sx, cy * sy])
    return Camera(camera.name, "PINHOLE", int(width), height, params, camera.R, camera.t)


def pixel_directions(camera: Camera) -> np.ndarray:
    """(H, W, 3) world direction (not normalised) of each pixel centre of a camera without
    distortion: the inverse of ``project_points`` (pixel (x, y)'s centre at (x + 0.5, y + 0.5))."""
    if np.any(camera.distortion):
        raise ValueError(f"pixel_directions: camera {camera.name} has distortion {camera.distortion.tolist()}")
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    ys, xs = np.mgrid[0 : camera.height, 0 : camera.width] + 0.5
    d_cam = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones_like(xs)], axis=-1)
    return d_cam @ np.asarray(camera.R, np.float64)  # R^T d_cam per pixel


def panorama_pixels(directions, width: int, height: int) -> np.ndarray:
    """(..., 2) continuous pixel coordinates (u, v) of camera-frame directions (..., 3) in a full
    equirectangular panorama of width x height (COLMAP's EQUIRECTANGULAR, nerfstudio's
    EQUIRECTANGULAR): longitude atan2(x, z) from the image's centre column, growing to the right,
    latitude asin(y / |d|) from the middle row, growing downwards (OpenCV's y); pixel (0, 0)'s
    centre at (0.5, 0.5), u in [0, W], v in [0, H]."""
    d = np.asarray(directions, np.float64)
    lon = np.arctan2(d[..., 0], d[..., 2])
    lat = np.arcsin(np.clip(d[..., 1] / np.linalg.norm(d, axis=-1), -1.0, 1.0))
    return np.stack([width * (0.5 + lon / (2 * np.pi)), height * (0.5 + lat / np.pi)], axis=-1)


# ---------------------------------------------------------------------------- transforms.json


def _image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) of an image file, or None if unreadable."""
    try:
        if path.suffix.lower() == ".exr":
            import OpenEXR

            with OpenEXR.File(str(path), header_only=True) as exr:
                lo, hi = exr.header()["dataWindow"]
            return int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
        import cv2

        img = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_UNCHANGED)
        return None if img is None else (int(img.shape[1]), int(img.shape[0]))
    except Exception:
        return None


def _resolve_image(base: Path, file_path: str) -> tuple[str, Path | None]:
    """Image name (relative, posix) and the file if found; tries common extensions if none given."""
    rel = Path(file_path.replace("\\", "/"))
    name = rel.as_posix()
    while name.startswith("./"):
        name = name[2:]
    candidate = base / name
    if candidate.is_file():
        return name, candidate
    if not rel.suffix:
        for ext in (".png", ".jpg", ".jpeg", ".exr"):
            if (base / (name + ext)).is_file():
                return name + ext, base / (name + ext)
    return name, None


def _pinhole_params(path: Path, field: str, w: float, h: float, model, number, get) -> tuple[list[float], str]:
    """COLMAP parameters and model of a transforms.json pinhole frame (``number``, ``get`` read a
    key of the frame, else of the top level)."""
    fx, fy = number("fl_x"), number("fl_y")
    angle_x, angle_y = number("camera_angle_x"), number("camera_angle_y")
    if fx is None and angle_x is not None:
        fx = 0.5 * w / math.tan(0.5 * angle_x)
    if fy is None and angle_y is not None:
        fy = 0.5 * h / math.tan(0.5 * angle_y)
    if fx is None and fy is not None:
        fx = fy
    if fy is None:
        fy = fx
    if fx is None:
        raise SceneError(path, f"{field} fl_x", "a focal length fl_x (pixels) or camera_angle_x (radians)")
    if fx <= 0 or fy <= 0:
        raise SceneError(path, f"{field} fl_x,fl_y", f"positive focal lengths, got {fx}, {fy}")
    cx, cy = number("cx", w / 2), number("cy", h / 2)
    dist = [number(k, 0.0) for k in ("k1", "k2", "p1", "p2")]
    for k in ("k3", "k4"):
        if (number(k, 0.0) or 0.0) != 0.0:
            raise SceneError(path, f"{field}.{k}", f"0 (the OPENCV model has k1, k2, p1, p2 only), got {get(k)}")
    if model is None:
        model = "OPENCV" if any(dist) else "PINHOLE"
    if model == "OPENCV":
        params = [fx, fy, cx, cy, *dist]
    elif any(dist):
        raise SceneError(path, f"{field} k1,k2,p1,p2", f"no distortion for camera_model {model}")
    elif model == "SIMPLE_PINHOLE":
        if not math.isclose(fx, fy, rel_tol=1e-9):
            raise SceneError(path, f"{field} fl_x,fl_y", f"fl_x == fl_y for SIMPLE_PINHOLE, got {fx}, {fy}")
        params = [fx, cx, cy]
    else:
        params = [fx, fy, cx, cy]
    return params, model


# nerfstudio's EQUIRECTANGULAR camera: fl_x = w / 2 (pi radians per half width), fl_y = h, the
# principal point at the centre; other values would be a crop or a shift of the sphere.
def _panorama_params(path: Path, field: str, w: float, h: float, number) -> list[float]:
    """COLMAP parameters (w, h) of a transforms.json panorama frame; intrinsics, when given, must
    be those of the full sphere (within half a pixel)."""
    for key, full in (("fl_x", w / 2), ("fl_y", h), ("cx", w / 2), ("cy", h / 2)):
        value = number(key)
        if value is not None and abs(value - full) > 0.5:
            raise SceneError(
                path,
                f"{field} {key}",
                f"{full:g} for an {PANORAMA_MODEL} camera of {w:g} x {h:g} (a full 360 x 180 degree panorama), "
                f"got {value:g}",
            )
    for key in ("k1", "k2", "k3", "k4", "p1", "p2"):
        if (number(key, 0.0) or 0.0) != 0.0:
            raise SceneError(path, f"{field} {key}", f"no distortion for an {PANORAMA_MODEL} camera, got {number(key)}")
    return [w, h]


def read_transforms_json(path, panoramas: bool = False) -> list[Camera]:
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SceneError(path, "(file)", f"a readable transforms.json ({exc})") from None
    except json.JSONDecodeError as exc:
        raise SceneError(path, "(document)", f"valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise SceneError(path, "(document)", "a JSON object")
    frames = doc.get("frames")
    if not isinstance(frames, list) or not frames:
        raise SceneError(path, "frames", "a non-empty list of frames")
    base = path.parent
    out = []
    for i, frame in enumerate(frames):
        field = f"frames[{i}]"
        if not isinstance(frame, dict):
            raise SceneError(path, field, "an object")

        def get(key, default=None):
            value = frame.get(key, doc.get(key, default))
            return value

        def number(key, default=None):
            value = get(key, default)
            if value is None:
                return None
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                where = f"{field}.{key}" if key in frame else key
                raise SceneError(path, where, f"a finite number, got {value!r}")
            return float(value)

        file_path = frame.get("file_path")
        if not isinstance(file_path, str) or not file_path:
            raise SceneError(path, f"{field}.file_path", "the image's path (a string)")
        name, image_file = _resolve_image(base, file_path)

        model = get("camera_model", None)
        if model is not None and model not in SUPPORTED_MODELS and not (panoramas and model == PANORAMA_MODEL):
            where = f"{field}.camera_model" if "camera_model" in frame else "camera_model"
            hint = f" {PANORAMA_HINT}" if model == PANORAMA_MODEL else ""
            raise SceneError(path, where, f"one of {', '.join(SUPPORTED_MODELS)}, got {model}{hint}")

        w, h = number("w"), number("h")
        if w is None or h is None:
            size = _image_size(image_file) if image_file is not None else None
            if size is None:
                raise SceneError(path, f"{field} w,h", f"image size w, h, or a readable image at {base / name}")
            w, h = (w or size[0]), (h or size[1])
        if model == PANORAMA_MODEL:
            params = _panorama_params(path, field, w, h, number)
        else:
            params, model = _pinhole_params(path, field, w, h, model, number, get)

        m = frame.get("transform_matrix")
        try:
            m = np.asarray(m, np.float64)
        except (TypeError, ValueError):
            m = np.zeros(0)
        if m.shape not in ((4, 4), (3, 4)) or not np.isfinite(m).all():
            raise SceneError(path, f"{field}.transform_matrix", "a 4x4 (or 3x4) camera-to-world matrix of numbers")
        rot_gl, center = m[:3, :3], m[:3, 3]
        rot = rot_gl @ GL_TO_CV  # camera-to-world rotation, OpenCV camera axes
        if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-4) or np.linalg.det(rot) <= 0:
            raise SceneError(
                path, f"{field}.transform_matrix", "a rigid camera-to-world transform (rotation without scale)"
            )
        u, _, vt = np.linalg.svd(rot)  # snap to the nearest rotation
        rot = u @ vt
        R = rot.T
        camera = Camera(
            name=name,
            model=model,
            width=int(round(w)),
            height=int(round(h)),
            params=np.asarray(params, np.float64),
            R=R,
            t=-R @ center,
        )
        (check_panorama if model == PANORAMA_MODEL else check_camera)(camera, path, f"{field} ({name})")
        out.append(camera)
    out.sort(key=lambda c: c.name)
    names = [c.name for c in out]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise SceneError(path, "frames file_path", f"unique image paths, {dup} appears twice")
    return out


# ---------------------------------------------------------------------------- the cameras stage


# Forward (z) and down (y) axes of the six cube-face cameras, in the order +X, -X, +Y, -Y, +Z, -Z.
CUBE_FACE_AXES = (
    ((1, 0, 0), (0, -1, 0)),
    ((-1, 0, 0), (0, -1, 0)),
    ((0, 1, 0), (0, 0, 1)),
    ((0, -1, 0), (0, 0, -1)),
    ((0, 0, 1), (0, -1, 0)),
    ((0, 0, -1), (0, -1, 0)),
)
CUBE_FACE_NAMES = ("px", "nx", "py", "ny", "pz", "nz")


def cube_face_cameras(center, size: int, name: str = "pano", rotation=None) -> list[Camera]:
    """A panorama as six 90-degree PINHOLE cameras at `center` (how MILO takes panoramas in):
    each face's frustum covers exactly its cube face, so the six images cover every direction
    once. Rotations are proper (det +1), as COLMAP requires, which makes each face image the
    mirror of an OpenGL cube-map face (left to right): cube maps are left-handed. `rotation`
    (3 x 3, world-to-panorama, default identity) turns the cube with the panorama: the faces are
    then the panorama's own (+Z its centre, -Y its top), so its poles fall on face centres.
    Images are named ``<name>_<face>.exr``, faces px, nx, py, ny, pz, nz."""
    center = np.asarray(center, np.float64)
    rotation = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
    cameras = []
    for face, (forward, down) in zip(CUBE_FACE_NAMES, CUBE_FACE_AXES):
        z, y = np.asarray(forward, np.float64), np.asarray(down, np.float64)
        R = np.stack([np.cross(y, z), y, z]) @ rotation  # rows: camera x (right), y (down), z (forward)
        params = np.array([size / 2, size / 2, size / 2, size / 2], np.float64)
        cameras.append(Camera(f"{name}_{face}.exr", "PINHOLE", size, size, params, R, -R @ center))
    return cameras
