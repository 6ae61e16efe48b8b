"""Triangle meshes out of any USD file (usd-core): every drawn UsdGeom.Mesh, its world transform
applied, in meters with +Y up, grouped by bound material (a model's parts).

What a user's furniture model needs (the asset library, docs/assets.md), not a scene: no UVs,
lights or cameras (`invrender import-usd` reads those from our own exports). Polygons are
fan-triangulated; a left-handed mesh or a mirroring transform has its winding flipped so
fronts stay counter-clockwise. Problems are one SceneError naming the file and the prim.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .types import SceneError

__all__ = ["read_usd_parts"]

Z_UP_TO_Y_UP = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], np.float64)


def _open(path: Path):
    from pxr import Tf, Usd

    try:
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as error:
        stage, reason = None, str(error).strip().splitlines()[-1]
    else:
        reason = ""
    if stage is None:
        raise SceneError(path, "(file)", f"a USD stage usd-core can open{': ' + reason if reason else ''}")
    return stage


def _stage_to_meters_y_up(stage) -> np.ndarray:
    from pxr import UsdGeom

    m = np.eye(4)
    m[:3, :3] *= UsdGeom.GetStageMetersPerUnit(stage)
    return Z_UP_TO_Y_UP @ m if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else m


def _triangles(counts: np.ndarray, indices: np.ndarray, path, prim) -> np.ndarray:
    if len(counts) == 0 or counts.min() < 3 or counts.sum() != len(indices):
        raise SceneError(path, f"{prim} faceVertexCounts", "polygons of at least 3 vertices summing to faceVertexIndices")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    first = np.repeat(starts, counts - 2)
    # Corner j of the fan of polygon k: (start, start + j, start + j + 1), j = 1 .. n - 2.
    j = np.arange(len(first)) - np.repeat(np.cumsum(counts - 2) - (counts - 2), counts - 2) + 1
    return indices[np.stack([first, first + j, first + j + 1], axis=1)]


def _mesh_prim(prim, to_meters: np.ndarray, path) -> tuple[np.ndarray, np.ndarray]:
    from pxr import Usd, UsdGeom

    mesh = UsdGeom.Mesh(prim)
    points = np.asarray(mesh.GetPointsAttr().Get() or [], np.float64).reshape(-1, 3)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], np.int64)
    faces = _triangles(counts, indices, path, prim.GetPath())
    if len(points) == 0 or faces.min() < 0 or faces.max() >= len(points):
        raise SceneError(path, f"{prim.GetPath()} faceVertexIndices", f"indices into its {len(points)} points")
    world = to_meters @ np.array(mesh.ComputeLocalToWorldTransform(Usd.TimeCode.Default()), np.float64).T
    positions = points @ world[:3, :3].T + world[:3, 3]
    flip = (mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded) != (np.linalg.det(world[:3, :3]) < 0)
    return positions, (faces[:, ::-1] if flip else faces).astype(np.int32)


def read_usd_parts(path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """[(part name, positions (V, 3) float64 meters +Y up, faces (F, 3) int32)], one per bound
    material (the material prim's name; a mesh without one is named after its prim)."""
    from pxr import Usd, UsdGeom, UsdShade

    path = Path(path)
    stage = _open(path)
    to_meters = _stage_to_meters_y_up(stage)
    parts: dict[str, list] = {}
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
        if not prim.IsA(UsdGeom.Mesh):
            continue
        imageable = UsdGeom.Imageable(prim)
        if imageable.ComputeVisibility() == UsdGeom.Tokens.invisible or imageable.ComputePurpose() in (
            UsdGeom.Tokens.guide,
            UsdGeom.Tokens.proxy,
        ):
            continue
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        name = material.GetPrim().GetName() if material else prim.GetName()
        parts.setdefault(name, []).append(_mesh_prim(prim, to_meters, path))
    if not parts:
        raise SceneError(path, "UsdGeom.Mesh", "at least one visible mesh prim")
    out = []
    for name, pieces in parts.items():
        offsets = np.cumsum([0] + [len(p) for p, _ in pieces[:-1]])
        out.append((name, np.concatenate([p for p, _ in pieces]), np.concatenate([f + o for (_, f), o in zip(pieces, offsets)])))
    return out
