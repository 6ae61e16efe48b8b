"""The object stage's measures: each object's mask IoU against its segment (exact z-buffer
labels, placement.label_image, not the differentiable renderer), and against a synthetic
capture's truth (truth/room.json's objects carry their segment ids) the retrieval's top-1 asset
and category, the position error (meters), the yaw error (degrees, modulo the true asset's
symmetry where the library knows it) and the relative scale error.

Truth and estimate need not share a world (room_box's world is its own box's, and the box's
axes are only known modulo 90 degrees), so positions and directions are compared in the photo's
camera frame, the estimate's lengths times ``truth_scale`` (room_box's: the truth's depth over the
photo's; 1 for a metric depth).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..scene.room_photo import yaw_matrix
from ..scene.types import Camera, SceneError
from .placement import Placement, label_image

__all__ = ["mask_ious", "read_truth", "truth_metrics", "yaw_error"]


def mask_ious(placements: list[Placement], masks: list[np.ndarray], camera: Camera) -> list[float]:
    """Each placement's visible exact mask (all placements hiding each other) against its segment's
    mask; ``camera`` at the masks' size."""
    labels, _ = label_image(placements, camera)
    out = []
    for i, mask in enumerate(masks):
        mine = labels == i
        union = (mine | mask).sum()
        out.append(round(float((mine & mask).sum() / union), 4) if union else None)
    return out


def read_truth(truth_dir) -> dict | None:
    """truth/room.json's objects by segment id and its camera (R, t), or None without one."""
    path = Path(truth_dir) / "room.json"
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
        objects = {int(o["segment"]): o for o in doc["objects"]}
        for o in objects.values():
            o["position"], o["yaw_deg"], o["scale"] = (
                np.asarray(o["position"], float),
                float(o["yaw_deg"]),
                float(o["scale"]),
            )
        R, t = np.asarray(doc["camera"]["R"], float).reshape(3, 3), np.asarray(doc["camera"]["t"], float).reshape(3)
    except (KeyError, TypeError, ValueError) as error:
        raise SceneError(
            path,
            "objects/camera",
            f"objects [{{segment, asset, position, yaw_deg, scale}}] and camera {{R, t}} ({error})",
        ) from None
    return {"objects": objects, "R": R, "t": t}


def yaw_error(estimate: np.ndarray, truth: np.ndarray, up: np.ndarray, symmetry: int) -> float | None:
    """Degrees between two forward directions (camera frame) turned about ``up``, modulo the
    asset's symmetry (``symmetry`` turns map it onto itself; 0: round, None returned)."""
    if symmetry == 0:
        return None
    flat = [v - (v @ up) * up for v in (estimate, truth)]
    angle = np.degrees(np.arctan2(np.cross(flat[1], flat[0]) @ up, flat[0] @ flat[1]))
    period = 360.0 / max(symmetry, 1)
    d = angle % period
    return float(min(d, period - d))


def _forward(yaw_deg: float) -> np.ndarray:
    return yaw_matrix(yaw_deg) @ np.array([0.0, 0.0, 1.0])


def truth_metrics(
    estimates: dict[int, Placement | None],
    camera: Camera,
    units: float,
    truth: dict,
    truth_scale: float,
    symmetry: dict[str, int],
    in_photo: set[int] | None = None,
) -> dict:
    """Per truth object (by segment): the estimate's asset and category match, position error (m),
    yaw error (deg), scale error (relative); and their means. ``estimates`` by segment id, in
    normalised units (``units`` times them is room.json's); a truth object without an estimate
    counts as a miss in the accuracies and is left out of the errors, unless its segment has no
    pixel in the photo (not in ``in_photo``, the segment ids the photo shows): then it is listed
    and left out of everything (the office's shelf, out of view)."""
    R, t = np.asarray(camera.R), np.asarray(camera.t) * units
    up = truth["R"][:, 1]
    rows = {}
    for segment, true in sorted(truth["objects"].items()):
        place = estimates.get(segment)
        if place is None:
            seen = in_photo is None or segment in in_photo
            rows[str(segment)] = {"found": False, "in_photo": seen, "asset": False, "category": False}
            continue
        mine = (R @ (place.position * units) + t) * truth_scale
        theirs = truth["R"] @ true["position"] + truth["t"]
        rows[str(segment)] = {
            "found": True,
            "asset": place.asset.name == true["asset"],
            "category": place.asset.category == true.get("category", true["asset"].rsplit("_", 1)[0]),
            "position_error": round(float(np.linalg.norm(mine - theirs)), 4),
            "yaw_error_deg": _rounded(
                yaw_error(
                    R @ _forward(place.yaw_deg),
                    truth["R"] @ _forward(true["yaw_deg"]),
                    up,
                    symmetry.get(true["asset"], 1),
                )
            ),
            "scale_error": round(abs(place.scale * units * truth_scale - true["scale"]) / true["scale"], 4),
        }
    return {"per_object": rows, **_means(rows)}


def _rounded(value):
    return None if value is None else round(value, 3)


def _means(rows: dict) -> dict:
    values = [r for r in rows.values() if r.get("in_photo", True)]
    found = [r for r in values if r["found"]]

    def mean(key, average=np.mean):
        xs = [r[key] for r in found if r.get(key) is not None]
        return round(float(average(xs)), 4) if xs else None

    return {
        "objects": len(values),
        "asset_accuracy": round(float(np.mean([r["asset"] for r in values])), 4) if values else None,
        "category_accuracy": round(float(np.mean([r["category"] for r in values])), 4) if values else None,
        "position_error": mean("position_error"),
        "yaw_error_deg": mean("yaw_error_deg"),
        "scale_error": mean("scale_error"),
        # A wrong asset's yaw (a desk for a cabinet) or a near-cube's (known modulo 90 degrees)
        # weighs on the mean; the median says how the rest fare.
        "position_error_median": mean("position_error", np.median),
        "yaw_error_deg_median": mean("yaw_error_deg", np.median),
    }
