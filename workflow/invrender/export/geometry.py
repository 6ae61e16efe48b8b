"""Pieces of the scene's mesh <-> UsdGeom.Mesh prims.

Our mesh splits a vertex wherever the atlas has a seam (one position, two UVs). A USD mesh is
better welded: its points are the distinct positions, and `st` is a face-varying primvar whose
values are our per-vertex UVs and whose indices are our faces. That keeps everything: the
scene's vertex k of a piece is `st` value k, its position the point of any corner that indexes it.
A piece without seams keeps one point per vertex and a per-vertex `st`.

Faces and normals follow our conventions: triangles counter-clockwise seen from the front (USD's
rightHanded orientation), flat normals (face-varying, one per face), double-sided (our emission
and reflection are), no subdivision. The scene's face and vertex numbers of each piece are kept
in invrender: attributes (schema.py), so the importer can restore the mesh in its order: the
renderer's emitter sampling, and so its noise, depends on the face order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import Sdf, Usd, UsdGeom, Vt

from ..scene.types import Mesh, SceneError
from . import schema

__all__ = [
    "MeshPiece",
    "piece_of",
    "weld",
    "face_normals",
    "connected_faces",
    "author_mesh",
    "read_mesh",
    "authored_value",
]


@dataclass
class MeshPiece:
    """Part of a mesh in some frame: its own vertices (position, uv), faces into them, and, when it
    came from a scene, the scene's number of each face and vertex."""

    positions: np.ndarray  # (n, 3) float32
    uvs: np.ndarray  # (n, 2) float32
    faces: np.ndarray  # (m, 3) int32, into positions
    face_ids: np.ndarray | None = None  # (m,) the scene's face index of each face
    vertex_ids: np.ndarray | None = None  # (n,) the scene's vertex index of each vertex
    instance_id: int = 0


def piece_of(mesh: Mesh, face_ids: np.ndarray, instance_id: int = 0) -> MeshPiece:
    """The faces `face_ids` of `mesh` with the vertices they use (in the mesh's vertex order)."""
    face_ids = np.asarray(face_ids, np.int64)
    vertex_ids, local = np.unique(mesh.faces[face_ids], return_inverse=True)
    return MeshPiece(
        positions=mesh.positions[vertex_ids],
        uvs=mesh.uvs[vertex_ids],
        faces=local.reshape(-1, 3).astype(np.int32),
        face_ids=face_ids,
        vertex_ids=vertex_ids,
        instance_id=int(instance_id),
    )


def weld(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct positions in order of first appearance, and the point index of each vertex."""
    _, first, inverse = np.unique(positions, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # unique's order is sorted by value: renumber by first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return positions[first[order]], rank[inverse.reshape(-1)]


def face_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit geometric normal of each face, counter-clockwise front; +Y for a degenerate face."""
    p = points[faces].astype(np.float64)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.where(length > 0, length, 1.0), [0.0, 1.0, 0.0]).astype(np.float32)


def connected_faces(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """A label per face: faces sharing a position (not just a vertex: seams split vertices) get
    the same label. Labels are 0.. in order of each group's first face."""
    points, point_of = weld(positions)
    corners = point_of[faces]  # (m, 3)
    a, b = np.concatenate([corners[:, 0], corners[:, 1]]), np.concatenate([corners[:, 1], corners[:, 2]])
    root = np.arange(len(points))
    while True:  # union-find on the edges: hook the larger root under the smaller, then flatten
        ra, rb = root[a], root[b]
        if np.array_equal(ra, rb):
            break
        np.minimum.at(root, np.maximum(ra, rb), np.minimum(ra, rb))
        while not np.array_equal(root, root[root]):
            root = root[root]
    face_label = root[corners[:, 0]]
    _, first, inverse = np.unique(face_label, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))  # number the groups by their first face
    return rank[inverse.reshape(-1)]


def _int_array(values) -> Vt.IntArray:
    return Vt.IntArray.FromNumpy(np.ascontiguousarray(values, np.int32))


def author_mesh(stage: Usd.Stage, path: str, piece: MeshPiece, keep_indices: bool = True) -> UsdGeom.Mesh:
    """A UsdGeom.Mesh of a piece (module docstring). With keep_indices its scene face and vertex
    numbers and instance id go on the prim (instanced pieces keep them on their instance instead)."""
    points, point_of = weld(piece.positions)
    mesh = UsdGeom.Mesh.Define(stage, path)
    faces = np.asarray(piece.faces, np.int64)
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray)
    if len(points) == len(piece.positions):  # no seams: one point per vertex
        points, corners = piece.positions, faces
        st.SetInterpolation(UsdGeom.Tokens.vertex)
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(piece.uvs, np.float32)))
    else:
        corners = point_of[faces]
        st.SetInterpolation(UsdGeom.Tokens.faceVarying)
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(piece.uvs, np.float32)))
        st.SetIndices(_int_array(faces.ravel()))
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, np.float32)))
    mesh.CreateFaceVertexCountsAttr(_int_array(np.full(len(faces), 3)))
    mesh.CreateFaceVertexIndicesAttr(_int_array(corners.ravel()))
    normals = np.repeat(face_normals(points, corners), 3, axis=0)
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(normals))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.faceVarying)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)
    lo, hi = points.min(axis=0), points.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([lo, hi]).astype(np.float32)))
    if keep_indices:
        write_indices(mesh.GetPrim(), piece)
    return mesh


def write_indices(prim: Usd.Prim, piece: MeshPiece) -> None:
    """The scene's face and vertex numbers and the instance id of a piece, on `prim`."""
    if piece.face_ids is not None:
        prim.CreateAttribute(schema.FACE_INDICES, Sdf.ValueTypeNames.IntArray, custom=True).Set(
            _int_array(piece.face_ids)
        )
        prim.CreateAttribute(schema.VERTEX_INDICES, Sdf.ValueTypeNames.IntArray, custom=True).Set(
            _int_array(piece.vertex_ids)
        )
    prim.CreateAttribute(schema.INSTANCE_ID, Sdf.ValueTypeNames.Int, custom=True).Set(int(piece.instance_id))


def _fan(counts: np.ndarray, where: str) -> np.ndarray:
    """Corner numbers (k, 3) of the fan triangulation of polygons with `counts` corners, in order."""
    if np.any(counts < 3):
        raise SceneError(where, "faceVertexCounts", "polygons of at least 3 corners")
    per_polygon = counts - 2
    first = np.repeat(np.cumsum(counts) - counts, per_polygon)
    j = np.arange(per_polygon.sum()) - np.repeat(np.cumsum(per_polygon) - per_polygon, per_polygon) + 1
    return np.stack([first, first + j, first + j + 1], axis=1)


def _array(attr, dtype, width: int | None = None, where: str = "") -> np.ndarray | None:
    value = attr.Get() if attr else None
    if value is None:
        return None
    out = np.asarray(value, dtype)
    return out.reshape(-1, width) if width else out.reshape(-1)


def authored_value(prim: Usd.Prim, name: str):
    attr = prim.GetAttribute(name)
    return attr.Get() if attr and attr.HasAuthoredValue() else None


def read_mesh(prim: Usd.Prim, indices_prim: Usd.Prim | None = None) -> MeshPiece:
    """A UsdGeom.Mesh as a piece in its own frame: triangles (polygons fan-triangulated), one vertex
    per `st` value (face-varying) or per point (vertex `st`, or none: uv 0). The scene's numbers and
    instance id are read from `indices_prim` (the instance of an instanced mesh), else the mesh."""
    where = str(prim.GetPath())
    mesh = UsdGeom.Mesh(prim)
    points = _array(mesh.GetPointsAttr(), np.float32, 3)
    counts = _array(mesh.GetFaceVertexCountsAttr(), np.int64)
    corners = _array(mesh.GetFaceVertexIndicesAttr(), np.int64)
    if points is None or counts is None or corners is None or len(corners) != counts.sum():
        raise SceneError(where, "points, faceVertexCounts, faceVertexIndices", "a complete mesh")
    if len(corners) and (corners.min() < 0 or corners.max() >= len(points)):
        raise SceneError(where, "faceVertexIndices", f"indices into {len(points)} points")
    triangles = _fan(counts, where)

    st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    interpolation = st.GetInterpolation() if st and st.HasAuthoredValue() else None
    if interpolation == UsdGeom.Tokens.faceVarying:
        values = _array(st.GetAttr(), np.float32, 2)
        st_index = _array(st.GetIndicesAttr(), np.int64) if st.IsIndexed() else np.arange(len(corners))
        if len(st_index) != len(corners) or (len(st_index) and st_index.max() >= len(values)):
            raise SceneError(where, "primvars:st", "one face-varying value (or index) per corner")
        positions = np.zeros((len(values), 3), np.float32)
        positions[st_index[::-1]] = points[corners[::-1]]  # the first corner of each vertex wins
        uvs, faces = values, st_index[triangles]
    elif interpolation in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        values = st.ComputeFlattened() if st.IsIndexed() else st.Get()
        uvs = np.asarray(values, np.float32).reshape(-1, 2)
        if len(uvs) != len(points):
            raise SceneError(where, "primvars:st", f"one value per point ({len(points)})")
        positions, faces = points, corners[triangles]
    else:
        positions, uvs, faces = points, np.zeros((len(points), 2), np.float32), corners[triangles]

    source = indices_prim or prim
    face_ids = _array(source.GetAttribute(schema.FACE_INDICES), np.int64)
    vertex_ids = _array(source.GetAttribute(schema.VERTEX_INDICES), np.int64)
    if face_ids is None or vertex_ids is None or len(face_ids) != len(faces) or len(vertex_ids) != len(positions):
        face_ids = vertex_ids = None  # not ours, or its topology was edited: keep its own order
    instance_id = authored_value(source, schema.INSTANCE_ID)
    return MeshPiece(
        positions=positions,
        uvs=uvs,
        faces=faces.astype(np.int32),
        face_ids=face_ids,
        vertex_ids=vertex_ids,
        instance_id=int(instance_id or 0),
    )
