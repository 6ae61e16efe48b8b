"""poses.json: the pose of each copy of an object (the duplicates mode's output).

    {"convention": "p_world = T_obj2world @ [p_obj, 1]; ...",
     "instances": [{"instance_id": 1, "mask_value": 1, "registered": true,
                    "T_obj2world": [[r, r, r, tx], [r, r, r, ty], [r, r, r, tz], [0, 0, 0, 1]]}, ...]}

`instance_id` is the copy's id in the masks that go with the poses (the duplicates stage's: the
segment stage's renumbered id, its pixels' value in segmentation/masks); `mask_value` (or
`mask_file`, for a folder of masks) is how the user's own masks name it, so a pose maps back to the
object it came from. T_obj2world is row-major and rigid (a rotation and a translation: the copies are the same object,
not scaled ones); `registered: false` marks a copy whose pose was not recovered (it is skipped).
A v2 scene says the same directly: objects sharing one mesh and material set, each with its own
transform (docs/scene-format.md).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .atomic import atomic_path
from .types import Mesh, SceneError, SceneObject

__all__ = ["validate_poses", "read_poses", "write_poses", "placements"]


def validate_poses(doc, where) -> list[dict]:
    """The registered instances of a poses document, each {"instance_id", "T"} with T a 4x4
    float64; one SceneError naming `where` and the field for anything else."""
    if not isinstance(doc, dict) or not isinstance(doc.get("instances"), list):
        raise SceneError(where, "instances", "a list of {instance_id, registered, T_obj2world}")
    out = []
    for k, entry in enumerate(doc["instances"]):
        field_name = f"instances[{k}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("instance_id"), int):
            raise SceneError(where, f"{field_name}.instance_id", "an integer instance id")
        try:
            T = np.asarray(entry.get("T_obj2world"), np.float64)
        except (TypeError, ValueError):
            T = np.zeros(0)
        if T.shape != (4, 4) or not np.isfinite(T).all() or not np.allclose(T[3], [0, 0, 0, 1]):
            raise SceneError(where, f"{field_name}.T_obj2world", "a row-major 4x4 rigid transform [[R, t], [0, 1]]")
        R = T[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
            raise SceneError(where, f"{field_name}.T_obj2world", "a rotation in its upper 3x3 (rigid pose, no scale)")
        if entry.get("registered", True):
            out.append({"instance_id": entry["instance_id"], "T": T})
    return out


def read_poses(path) -> dict:
    """Read and validate a poses.json; returns the document."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing poses.json (the duplicates stage's duplicates/poses.json)")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(path, "(document)", f"a readable JSON document ({exc})") from None
    validate_poses(doc, path)
    return doc


def write_poses(path, doc: dict) -> None:
    """Validate a poses document and write it (indented JSON), atomically."""
    validate_poses(doc, path)
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


def placements(doc, mesh: Mesh, material: str, name: str = "object", where="poses.json") -> list[SceneObject]:
    """The registered copies of a poses document as v2 objects: `mesh` (in the object frame)
    placed at each T_obj2world with the instance id as its own, all sharing `material`."""
    return [
        SceneObject(f"{name}_{pose['instance_id']}", mesh, material, pose["T"], instance_id=pose["instance_id"])
        for pose in validate_poses(doc, where)
    ]
