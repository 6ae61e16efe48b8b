"""The room photo capture (mode `room`, PSDR-Room section 4.1): one photograph and, where the
user has them, a depth map, a panoptic segmentation and the field of view.

    photo.exr | photo.png | photo.jpg   the photograph (EXR linear; PNG/JPEG sRGB). An EXR and
                                        its PNG preview count as one: the EXR is read. Without
                                        any, images/ holding one image (the config's layout).
    depth.exr       one channel (Y, or R of RGB), any scale; 0 = no depth
    panoptic.png    uint16 (or uint8) segment ids, 0 = unlabelled
    panoptic.json   {"segments": [{"id": 1, "class": "wall", "name": "wall_-z"}, ...]}
                    (or panoptic.csv: a header ``id,class[,name]`` and one row per segment)
    camera.json     {"width", "height", "fov_y_deg"} (vertical field of view; ``fov_x_deg``,
                    the horizontal one, is taken instead)
    truth/          synthetic captures only (synthesize/room_photo.py)

Nothing here is estimated: no learned depth or segmentation can be downloaded, so a stage that
needs them calls ``RoomPhoto.require`` and stops naming what to provide. The field of view, when
absent, is estimated from vanishing points (``scene/vanishing.py``).
"""

from __future__ import annotations

import csv
import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import atomic_path
from .images import check_finite, read_image, read_mask, write_exr, write_mask, write_png_preview
from .types import SceneError

__all__ = [
    "ROOM_CLASSES",
    "yaw_matrix",
    "RoomPhoto",
    "load_room_photo",
    "write_room_photo",
    "fov_x_to_y",
    "fov_y_to_x",
    "PHOTO_NAMES",
    "DEPTH_NAME",
    "IDS_NAME",
    "LABELS_NAME",
    "CAMERA_NAME",
]


def yaw_matrix(yaw_deg: float) -> np.ndarray:
    """Rotation about the room's +Y (up) by ``yaw_deg``, counter-clockwise seen from above: the one
    convention of every room box, object and light (room.json's ``yaw_deg``)."""
    a = np.radians(yaw_deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


ROOM_CLASSES = ("wall", "floor", "ceiling", "window", "lamp", "object")

PHOTO_NAMES = ("photo.exr", "photo.png", "photo.jpg", "photo.jpeg")  # the first present is read
DEPTH_NAME = "depth.exr"
IDS_NAME = "panoptic.png"
LABELS_NAME = "panoptic.json"
LABELS_CSV = "panoptic.csv"
CAMERA_NAME = "camera.json"
log = logging.getLogger(__name__)
IMAGE_SUFFIXES = (".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff")

# What a stage asks for, and what the user provides for it (the message of RoomPhoto.require).
PROVIDE = {
    "depth": (
        f"a depth map: {DEPTH_NAME} in the capture (one channel, any scale, 0 = unknown) or the "
        "config's capture.depth; no depth estimator can be downloaded here (use a depth sensor or "
        "a monocular estimator such as DPT/MiDaS elsewhere)"
    ),
    "segmentation": (
        f"a panoptic segmentation: {IDS_NAME} (segment ids, 0 = unlabelled) and {LABELS_NAME} "
        f"(each id's class, one of {', '.join(ROOM_CLASSES)}) in the capture, or the config's "
        "capture.segmentation {ids, labels}; no segmentation model can be downloaded here (use "
        "Mask2Former or a labelling tool elsewhere)"
    ),
}


def fov_x_to_y(fov_x_deg: float, width: int, height: int) -> float:
    """The vertical field of view of a pinhole with square pixels and this horizontal one."""
    return math.degrees(2 * math.atan(math.tan(math.radians(fov_x_deg) / 2) * height / width))


def fov_y_to_x(fov_y_deg: float, width: int, height: int) -> float:
    return fov_x_to_y(fov_y_deg, height, width)


@dataclass
class RoomPhoto:
    """A room capture as read: arrays indexed [y, x]."""

    image: np.ndarray  # (H, W, 3) linear RGB float32
    depth: np.ndarray | None  # (H, W) float32 as given (any scale), 0 = no depth
    segments: np.ndarray | None  # (H, W) int32 segment ids, 0 = unlabelled
    labels: dict[int, tuple[str, str]] | None  # id -> (class, name)
    fov_y_deg: float | None  # vertical field of view, None when the capture gives none
    paths: dict[str, Path] = field(default_factory=dict)  # "photo", "depth", "ids", "labels", "camera"

    @property
    def height(self) -> int:
        return int(self.image.shape[0])

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    def require(self, *what: str) -> None:
        """Stop, naming what to provide, when any of ``what`` ("depth", "segmentation") is missing."""
        missing = [w for w in what if (self.depth if w == "depth" else self.segments) is None]
        if missing:
            where = self.paths.get("capture", self.paths.get("photo", "capture"))
            expected = "; and ".join(PROVIDE[w] for w in missing)
            raise SceneError(where, " and ".join(missing), f"{expected} (missing)")

    def normalised_depth(self) -> np.ndarray:
        """Depth divided by its median over the pixels that have one (the paper's normalised
        depth: a user's depth has any scale), 0 where there is none."""
        self.require("depth")
        valid = self.depth > 0
        return np.where(valid, self.depth / np.median(self.depth[valid]), 0.0).astype(np.float32)

    def field_of_view(self) -> tuple[float, str]:
        """(vertical field of view in degrees, where it came from): the capture's (camera.json or
        the config), else the estimate from vanishing points (scene/vanishing.py), said in the log;
        a photograph with too few lines for one stops, naming what to give."""
        if self.fov_y_deg is not None:
            return self.fov_y_deg, "given"
        from .vanishing import estimate_fov

        log.info(
            "%s: no field of view given (camera.json or the config's capture.field_of_view): "
            "estimating it from vanishing points",
            self.paths.get("photo"),
        )
        estimate = estimate_fov(self.image)
        if estimate is None:
            raise SceneError(
                self.paths.get("capture", "capture"),
                "field of view",
                f"{CAMERA_NAME} with fov_y_deg, or the config's capture.field_of_view (the photograph "
                "has too few straight lines to estimate it from vanishing points)",
            )
        return estimate.fov_y_deg, "vanishing points"

    def class_mask(self, name: str) -> np.ndarray:
        """(H, W) bool: the pixels whose segment has class ``name``."""
        if name not in ROOM_CLASSES:
            raise ValueError(f"class_mask: expected one of {ROOM_CLASSES}, got {name!r}")
        self.require("segmentation")
        ids = [i for i, (cls, _) in self.labels.items() if cls == name]
        return np.isin(self.segments, ids)


# ---------------------------------------------------------------------------- reading


def _find_photo(capture: Path) -> Path:
    for name in PHOTO_NAMES:
        if (capture / name).is_file():
            return capture / name
    images = capture / "images"
    if images.is_dir():  # the config's layout: images/ with one photograph (an EXR before its PNG)
        stems = {}
        for path in sorted(images.iterdir()):
            if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
                best = stems.get(path.stem)
                rank = IMAGE_SUFFIXES.index(path.suffix.lower())
                if best is None or rank < IMAGE_SUFFIXES.index(best.suffix.lower()):
                    stems[path.stem] = path
        if len(stems) == 1:
            return next(iter(stems.values()))
    raise SceneError(
        capture, "photo", f"the room's photograph: one of {', '.join(PHOTO_NAMES)} (or images/ with one image)"
    )


def _read_photo(path: Path) -> np.ndarray:
    image = read_image(path)  # SceneError for a missing or undecodable file
    if image.shape[2] == 1:
        image = np.repeat(image, 3, axis=2)  # a grey photograph
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise SceneError(path, "size", f"a photograph, got {image.shape[1]} x {image.shape[0]} pixels")
    return np.ascontiguousarray(image[..., :3], np.float32)


def _check_size(path: Path, array: np.ndarray, photo: Path, shape) -> None:
    if array.shape[:2] != tuple(shape):
        raise SceneError(
            path,
            "size",
            f"{shape[1]} x {shape[0]} pixels as the photo {photo.name}, got {array.shape[1]} x {array.shape[0]}",
        )


def _read_depth(path: Path, photo: Path, shape) -> np.ndarray:
    if path.suffix.lower() != ".exr":
        raise SceneError(path, "(file)", "an OpenEXR depth map (.exr, one channel, any scale)")
    depth = check_finite(read_image(path, finite=False), path)[..., 0]  # Y, or R of RGB
    _check_size(path, depth, photo, shape)
    if (depth < 0).any():
        y, x = np.argwhere(depth < 0)[0]
        raise SceneError(path, f"pixel (x {x}, y {y})", f"a depth >= 0 (0 = unknown), got {depth[y, x]}")
    if not (depth > 0).any():
        raise SceneError(path, "values", "some positive depth (it is all 0, which means unknown)")
    return depth.astype(np.float32)


def _segment_rows(path: Path) -> list[dict]:
    """The label table's rows as dicts with "id", "class" and maybe "name"."""
    try:
        text = path.read_text()
    except OSError as error:
        raise SceneError(path, "(file)", f"a readable label table ({error.strerror})") from None
    if path.suffix.lower() == ".csv":
        rows = list(csv.DictReader(text.splitlines()))
        if rows and not {"id", "class"} <= set(rows[0]):
            raise SceneError(path, "header", f"columns id,class[,name], got {','.join(rows[0])}")
        return rows
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise SceneError(path, "(file)", f"JSON ({error.msg} at line {error.lineno})") from None
    if not isinstance(data, dict) or not isinstance(data.get("segments"), list):
        raise SceneError(path, "segments", 'a list: {"segments": [{"id": 1, "class": "wall"}, ...]}')
    return data["segments"]


def _read_labels(path: Path) -> dict[int, tuple[str, str]]:
    labels = {}
    for i, row in enumerate(_segment_rows(path)):
        if not isinstance(row, dict):
            raise SceneError(path, f"segments[{i}]", 'an object {"id", "class", "name"}')
        try:
            sid = int(row.get("id"))
        except (TypeError, ValueError):
            sid = None
        if sid is None or str(row.get("id")).strip() != str(sid) or not 0 < sid <= 65535:
            raise SceneError(path, f"segments[{i}].id", f"an integer id in 1..65535, got {row.get('id')!r}")
        cls = row.get("class")
        if cls not in ROOM_CLASSES:
            raise SceneError(path, f"segments[{i}].class", f"one of {', '.join(ROOM_CLASSES)}, got {cls!r}")
        if sid in labels:
            raise SceneError(path, f"segments[{i}].id", f"each id once, got {sid} twice")
        labels[sid] = (cls, str(row.get("name") or f"{cls}_{sid}"))
    return labels


def _read_segmentation(ids_path: Path, labels_path: Path, photo: Path, shape):
    segments = read_mask(ids_path).astype(np.int32)
    _check_size(ids_path, segments, photo, shape)
    labels = _read_labels(labels_path)
    present = np.unique(segments)
    unlabelled = [int(i) for i in present if i != 0 and i not in labels]
    if unlabelled:
        raise SceneError(
            ids_path,
            f"segment id {unlabelled[0]}",
            f"a label in {labels_path.name} for every id in the image (ids without one: "
            f"{', '.join(map(str, unlabelled[:10]))})",
        )
    return segments, labels


def _read_camera(path: Path, shape) -> float:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise SceneError(path, "(file)", f'JSON {{"width", "height", "fov_y_deg"}} ({error})') from None
    if not isinstance(data, dict):
        raise SceneError(path, "(file)", 'a JSON object {"width", "height", "fov_y_deg"}')
    h, w = shape
    for key, value in (("width", w), ("height", h)):
        if key in data and data[key] != value:
            raise SceneError(path, key, f"{value} as the photo, got {data[key]!r}")
    key = "fov_y_deg" if "fov_y_deg" in data else "fov_x_deg" if "fov_x_deg" in data else None
    if key is None:
        raise SceneError(path, "fov_y_deg", "the vertical field of view in degrees (or fov_x_deg, the horizontal)")
    fov = data[key]
    if isinstance(fov, bool) or not isinstance(fov, (int, float)) or not 0 < fov < 180:
        raise SceneError(path, key, f"degrees in (0, 180), got {fov!r}")
    return float(fov) if key == "fov_y_deg" else fov_x_to_y(fov, w, h)


def _given(capture: Path, path, default: str) -> Path | None:
    """A file the caller names (relative to the capture), else the capture's default, if there."""
    if path is not None:
        path = capture / path
        if not path.exists():
            raise SceneError(path, "(file)", "an existing file (a relative path is relative to the capture)")
        return path
    return capture / default if (capture / default).is_file() else None


def load_room_photo(
    capture_dir,
    photo=None,
    depth=None,
    ids=None,
    labels=None,
    fov_y_deg: float | None = None,
    require: tuple[str, ...] = (),
) -> RoomPhoto:
    """Read and check a room capture. The files are the layout above unless named (relative to
    the capture: a user's config); ``fov_y_deg`` given wins over camera.json. ``require``
    ("depth", "segmentation") turns a missing one into the SceneError naming what to provide."""
    capture = Path(capture_dir)
    if not capture.is_dir():
        raise SceneError(capture, "(directory)", "an existing room capture directory")
    photo_path = capture / photo if photo is not None else _find_photo(capture)
    image = _read_photo(photo_path)
    shape = image.shape[:2]
    paths = {"capture": capture, "photo": photo_path}

    depth_path = _given(capture, depth, DEPTH_NAME)
    depth_map = None if depth_path is None else _read_depth(depth_path, photo_path, shape)

    ids_path = _given(capture, ids, IDS_NAME)
    labels_path = _given(capture, labels, LABELS_NAME)
    if labels is None and labels_path is None and (capture / LABELS_CSV).is_file():
        labels_path = capture / LABELS_CSV
    segments = table = None
    if (ids_path is None) != (labels_path is None):
        have, lack = (ids_path, LABELS_NAME) if labels_path is None else (labels_path, IDS_NAME)
        raise SceneError(have, "segmentation", f"its other half beside it: {lack} ({PROVIDE['segmentation']})")
    if ids_path is not None:
        segments, table = _read_segmentation(ids_path, labels_path, photo_path, shape)

    camera_path = capture / CAMERA_NAME
    if fov_y_deg is None and camera_path.is_file():
        fov_y_deg = _read_camera(camera_path, shape)
    elif fov_y_deg is not None and not 0 < fov_y_deg < 180:
        raise SceneError(capture, "fov_y_deg", f"degrees in (0, 180), got {fov_y_deg!r}")
    for name, path in (("depth", depth_path), ("ids", ids_path), ("labels", labels_path)):
        if path is not None:
            paths[name] = path
    if camera_path.is_file():
        paths["camera"] = camera_path
    room = RoomPhoto(image, depth_map, segments, table, fov_y_deg, paths)
    room.require(*require)
    return room


# ---------------------------------------------------------------------------- writing


def write_room_photo(
    out_dir,
    image: np.ndarray,
    depth: np.ndarray | None = None,
    segments: np.ndarray | None = None,
    labels: dict[int, tuple[str, str]] | None = None,
    fov_y_deg: float | None = None,
) -> None:
    """Write a capture in the layout above into ``out_dir`` (an existing directory, typically
    an ``atomic_dir``'s temporary one): photo.exr and its sRGB preview photo.png, and what is given."""
    out = Path(out_dir)
    h, w = image.shape[:2]
    write_exr(out / "photo.exr", image)
    write_png_preview(out / "photo.png", image)
    if depth is not None:
        write_exr(out / DEPTH_NAME, np.asarray(depth, np.float32))
    if segments is not None:
        write_mask(out / IDS_NAME, segments)
        rows = [{"id": int(i), "class": c, "name": n} for i, (c, n) in sorted(labels.items())]
        _write_json(out / LABELS_NAME, {"segments": rows})
    if fov_y_deg is not None:
        _write_json(out / CAMERA_NAME, {"width": int(w), "height": int(h), "fov_y_deg": float(fov_y_deg)})


def _write_json(path: Path, data) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1) + "\n")
