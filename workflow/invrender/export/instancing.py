"""Duplicates as USD native instancing: one prototype mesh, one instance per recovered pose.

The duplicates mode recovers one shared mesh and material and a pose per copy (scene/poses.py:
`duplicates/poses.json`, `{"convention", "instances": [{"instance_id", "mask_value",
"registered", "T_obj2world"}]}`, p_world = T [p_obj, 1]). In the scene directory each copy is
the faces whose instance id is the pose's, all sharing the object's atlas UVs. The prototype is
the first registered copy moved back into the object frame by its pose; every copy is checked
against it before it becomes an instance: the same triangles over the same UVs, and its vertices
within `tolerance` of T applied to the prototype's. A copy that fails stays a plain mesh (a
warning says why), so an export never shows geometry the scene does not have.

Instancing costs exactness: a copy comes back as float32(T p) of a float32 prototype, within a
float32 rounding or two of the scene's positions (docs/export.md has the measured round trip).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..scene.types import Mesh
from .geometry import MeshPiece, piece_of

__all__ = ["Copy", "Duplicates", "find_duplicates"]

log = logging.getLogger(__name__)


@dataclass
class Copy:
    instance_id: int
    T: np.ndarray  # (4, 4) object to world
    face_ids: np.ndarray  # the scene's faces of this copy, in the prototype's face order
    vertex_ids: np.ndarray  # the scene's vertices, in the prototype's vertex order


@dataclass
class Duplicates:
    prototype: MeshPiece  # in the object frame, without scene numbers
    copies: list[Copy] = field(default_factory=list)

    def face_mask(self, face_count: int) -> np.ndarray:
        mask = np.zeros(face_count, bool)
        for copy in self.copies:
            mask[copy.face_ids] = True
        return mask


def _in_object_frame(piece: MeshPiece, T: np.ndarray) -> np.ndarray:
    return (piece.positions.astype(np.float64) - T[:3, 3]) @ T[:3, :3]  # R^T (p - t), row vectors


def find_duplicates(mesh: Mesh, poses: list[dict], eligible: np.ndarray, tolerance: float) -> Duplicates | None:
    """Copies of one object at the given poses (from scene.poses.validate_poses), among the `eligible` faces
    (a copy with a face that is not, e.g. one that emits, is left plain). None if there are none."""
    if mesh.instance_ids is None or not poses:
        return None
    duplicates = None
    for pose in poses:
        faces = np.flatnonzero(mesh.instance_ids == pose["instance_id"])
        if len(faces) == 0:
            log.warning("instance %d has a pose but no faces in the mesh: no instance", pose["instance_id"])
            continue
        if not eligible[faces].all():
            log.warning("instance %d emits or is a window opening: exported as a plain mesh", pose["instance_id"])
            continue
        piece = piece_of(mesh, faces, pose["instance_id"])
        local = _in_object_frame(piece, pose["T"])
        if duplicates is None:
            prototype = MeshPiece(positions=local.astype(np.float32), uvs=piece.uvs, faces=piece.faces)
            duplicates = Duplicates(prototype)
        else:
            reason = _mismatch(duplicates.prototype, piece, local, tolerance)
            if reason:
                log.warning(
                    "instance %d is not a copy of the prototype (%s): exported as a plain mesh",
                    pose["instance_id"],
                    reason,
                )
                continue
        duplicates.copies.append(Copy(pose["instance_id"], pose["T"], piece.face_ids, piece.vertex_ids))
    return duplicates


def _mismatch(prototype: MeshPiece, piece: MeshPiece, local: np.ndarray, tolerance: float) -> str:
    if piece.faces.shape != prototype.faces.shape or not np.array_equal(piece.faces, prototype.faces):
        return "different triangles"
    if not np.array_equal(piece.uvs, prototype.uvs):
        return "different UVs"
    error = float(np.abs(local - prototype.positions).max())
    if error > tolerance:
        return f"vertices {error:.3g} m off its pose, more than {tolerance:.3g} m"
    return ""
