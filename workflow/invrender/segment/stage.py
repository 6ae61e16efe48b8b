"""The `segment` stage: the instances of the repeated object in one photograph.

    out_dir/masks/<image stem>.png  uint16 instance ids, 0 = background, 1 .. N
    out_dir/instances.json          {"image", "width", "height", "backend", "instances": [{"id",
                                    "box": [x0, y0, x1, y1], "area", "score", ...}]}
    out_dir/overlay.png             the photograph, each instance tinted and numbered

Backends: ``opencv`` (opencv.py, the default: no downloaded weights) and ``provided``
(provided.py: a user's id image or a folder of masks). Either way ids are renumbered 1 .. N in
reading order of the boxes' top-left corners (top to bottom, then left to right), so the
numbering does not depend on a tool's labels; a provided instance keeps its original id (or
file name) as ``source``. Boxes are half-open pixel ranges, x1 and y1 exclusive.

The duplicates mode needs three views of the object at least, so fewer than ``min_instances``
(>= 3) stops with a message. The directory appears whole or not at all (``atomic_dir``).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import cv2
import numpy as np

from ..scene.atomic import atomic_dir, check_output
from ..scene.images import read_image, write_mask
from ..scene.types import SceneError
from .opencv import OpenCVSettings, segment_instances, to_srgb8
from .provided import read_provided

__all__ = ["run", "BACKENDS", "renumber", "instance_table", "overlay"]

logger = logging.getLogger(__name__)

BACKENDS = ("opencv", "provided")
MIN_INSTANCES = 3  # the duplicates mode's views: two are a stereo pair with no check


def _box(mask: np.ndarray) -> list[int]:
    ys, xs = np.nonzero(mask)
    return [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1]


def renumber(ids: np.ndarray) -> tuple[np.ndarray, dict[int, int]]:
    """Ids 1 .. N in reading order of their boxes' top-left corners (y, then x, then the old id
    for a tie); returns the new image and new id -> old id."""
    old = [int(i) for i in np.unique(ids) if i]
    order = sorted(old, key=lambda i: (*_box(ids == i)[1::-1], i))
    lut = np.zeros(int(ids.max()) + 1 if ids.size else 1, np.uint16)
    for new, i in enumerate(order, 1):
        lut[i] = new
    return lut[ids], {new: i for new, i in enumerate(order, 1)}


def instance_table(ids: np.ndarray, scores: dict[int, float]) -> list[dict]:
    """One entry per id 1 .. N: box, area (pixels), score."""
    table = []
    for i in range(1, int(ids.max()) + 1):
        mask = ids == i
        table.append({"id": i, "box": _box(mask), "area": int(mask.sum()), "score": round(float(scores[i]), 4)})
    return table


def _palette(n: int) -> np.ndarray:
    """n distinct saturated colours (BGR uint8): hues a golden-ratio step apart."""
    hues = (np.arange(n) * 0.618034 % 1.0 * 180).astype(np.uint8)
    hsv = np.stack([hues, np.full(n, 220, np.uint8), np.full(n, 255, np.uint8)], axis=1)[None]
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0]


def overlay(rgb: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """The photograph (sRGB, BGR uint8) with each instance tinted, outlined and numbered at its
    most interior pixel; enlarged by a whole factor to at least 640 pixels wide, so the numbers
    stay readable on a small image."""
    scale = max(1, int(np.ceil(640 / max(ids.shape[1], 1))))
    photo = cv2.resize(to_srgb8(rgb)[:, :, ::-1], None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    big = cv2.resize(ids, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    out = photo.copy()
    colours = _palette(int(ids.max()))
    for i in range(1, int(ids.max()) + 1):
        mask = (big == i).astype(np.uint8)
        colour = colours[i - 1].astype(np.float32)
        out[mask > 0] = (0.55 * photo[mask > 0] + 0.45 * colour).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, colour.tolist(), max(1, scale // 2))
        dist = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
        y, x = np.unravel_index(int(np.argmax(dist)), dist.shape)
        text, font, size = str(i), cv2.FONT_HERSHEY_SIMPLEX, max(0.6, out.shape[1] / 1280)
        (w, h), _ = cv2.getTextSize(text, font, size, max(2, round(2 * size)))
        org = (int(x - w / 2), int(y + h / 2))
        thick = max(2, round(2 * size))
        cv2.putText(out, text, org, font, size, (0, 0, 0), 2 * thick, cv2.LINE_AA)
        cv2.putText(out, text, org, font, size, (255, 255, 255), thick, cv2.LINE_AA)
    return out


def _check_settings(backend, masks, table, exemplar, min_instances, size) -> None:
    if backend not in BACKENDS:
        raise SceneError("segment --backend", "backend", f"one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "provided" and masks is None:
        raise SceneError("segment --masks", "masks", "an id image or a folder of masks for the provided backend")
    if backend != "provided" and (masks is not None or table is not None):
        raise SceneError(
            "segment --masks", "masks", f"no masks or table with the {backend} backend (they are for provided)"
        )
    if isinstance(min_instances, bool) or not isinstance(min_instances, int) or min_instances < MIN_INSTANCES:
        raise SceneError(
            "segment --min-instances",
            "instance count",
            f"an integer of at least {MIN_INSTANCES}, got {min_instances!r}",
        )
    if exemplar is not None:
        x0, y0, x1, y1 = (float(v) for v in exemplar)
        if not (0 <= x0 < x1 <= size[0] and 0 <= y0 < y1 <= size[1]):
            raise SceneError(
                "segment --exemplar",
                "exemplar box",
                f"x0 y0 x1 y1 inside the image (0 <= x0 < x1 <= {size[0]}, 0 <= y0 < y1 <= {size[1]}), "
                f"got {list(exemplar)}",
            )


def run(
    image,
    out_dir,
    backend: str = "opencv",
    masks=None,
    table=None,
    exemplar=None,
    min_instances: int = MIN_INSTANCES,
    settings: dict | None = None,
    log: logging.Logger = logger,
) -> dict:
    """Segment ``image`` (any format read_image reads) into instances; write ``out_dir``;
    return what is written as instances.json. ``masks``/``table``: the provided backend's
    inputs; ``exemplar`` (x0, y0, x1, y1 pixels of one copy) and ``settings`` (OpenCVSettings
    fields) the opencv backend's."""
    image, out_dir = Path(image), Path(out_dir)
    started = time.perf_counter()
    check_output(out_dir, "segment")  # before the work, not after it
    rgb = read_image(image)[:, :, :3]
    if rgb.shape[2] == 1:
        rgb = np.repeat(rgb, 3, axis=2)
    height, width = rgb.shape[:2]
    _check_settings(backend, masks, table, exemplar, min_instances, (width, height))
    if backend == "provided":
        found, sources = read_provided(masks, (width, height), image, table)
        ids, old_of = renumber(found)
        scores = {i: 1.0 for i in old_of}  # the user's masks: taken as certain
        source = Path(masks)
    else:
        fields = OpenCVSettings.__dataclass_fields__
        unknown = sorted(set(settings or {}) - set(fields) - {"exemplar"})
        if unknown:
            raise SceneError(
                "segment settings", unknown[0], f"one of {', '.join(k for k in fields if k != 'exemplar')}"
            )
        opts = OpenCVSettings(**(settings or {}), exemplar=tuple(exemplar) if exemplar is not None else None)
        found, found_scores = segment_instances(rgb, opts, log=log)
        ids, old_of = renumber(found)
        scores = {new: found_scores[old] for new, old in old_of.items()}
        sources, source = None, image
    count = int(ids.max()) if ids.size else 0
    if count < min_instances:
        raise SceneError(
            source,
            "instances",
            f"at least {min_instances} instances (the duplicates mode needs three views of the object), "
            f"found {count} with the {backend} backend",
        )
    instances = instance_table(ids, scores)
    if sources is not None:
        for entry in instances:
            entry["source"] = sources[old_of[entry["id"]]]
    report = {"image": str(image), "width": width, "height": height, "backend": backend, "instances": instances}
    with atomic_dir(out_dir, kind="segment") as tmp:
        tmp = Path(tmp)
        (tmp / "masks").mkdir()
        write_mask(tmp / "masks" / f"{image.stem}.png", ids)
        cv2.imwrite(str(tmp / "overlay.png"), overlay(rgb, ids))
        (tmp / "instances.json").write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
    log.info(
        "segment: %d instances (%s backend) in %s -> %s in %.2f s",
        count,
        backend,
        image,
        out_dir,
        time.perf_counter() - started,
    )
    return report
