"""Mesh pieces in and out of UsdGeom.Mesh, welding, light regions, fan triangulation, instancing."""

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from invrender.export.geometry import MeshPiece, author_mesh, connected_faces, read_mesh, weld
from invrender.export.instancing import find_duplicates
from invrender.scene.poses import validate_poses
from invrender.scene.types import Mesh, SceneError


def _seamed_square():
    """A unit square of two triangles whose diagonal is a seam: 6 vertices, 4 positions."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    uvs = np.array([[0, 0], [0.4, 0], [0.4, 0.4], [0.6, 0.6], [1, 1], [0.6, 1]], np.float32)
    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    return MeshPiece(positions, uvs, faces, face_ids=np.array([7, 3]), vertex_ids=np.arange(10, 16), instance_id=4)


def test_weld_keeps_first_appearance_order():
    points, point_of = weld(_seamed_square().positions)
    assert np.array_equal(points, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert np.array_equal(point_of, [0, 1, 2, 0, 2, 3])


def test_a_seamed_piece_is_welded_with_face_varying_st_and_comes_back_whole():
    piece = _seamed_square()
    stage = Usd.Stage.CreateInMemory()
    mesh = author_mesh(stage, "/m", piece)
    assert len(mesh.GetPointsAttr().Get()) == 4
    assert UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st").GetInterpolation() == UsdGeom.Tokens.faceVarying
    assert np.allclose(np.asarray(mesh.GetNormalsAttr().Get()), [0, 0, 1])  # counter-clockwise front
    back = read_mesh(mesh.GetPrim())
    for field in ("positions", "uvs", "faces", "face_ids", "vertex_ids"):
        assert np.array_equal(getattr(back, field), getattr(piece, field)), field
    assert back.instance_id == 4


def test_quads_are_fanned_in_order():
    stage = Usd.Stage.CreateInMemory()
    mesh = UsdGeom.Mesh.Define(stage, "/m")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0), (3, 0, 0)])
    mesh.CreateFaceVertexCountsAttr([4, 3, 5])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 1, 4, 5, 4, 6, 5, 2, 1])
    back = read_mesh(mesh.GetPrim())
    assert np.array_equal(back.faces, [[0, 1, 2], [0, 2, 3], [1, 4, 5], [4, 6, 5], [4, 5, 2], [4, 2, 1]])
    mesh.CreateFaceVertexCountsAttr([2, 5, 5])
    with pytest.raises(SceneError, match="at least 3 corners"):
        read_mesh(mesh.GetPrim())


def test_connected_faces_joins_across_seams_and_separates_islands():
    square = _seamed_square()
    positions = np.concatenate([square.positions, square.positions + [5, 0, 0]])
    faces = np.concatenate([square.faces, square.faces + 6])
    assert np.array_equal(connected_faces(positions, faces), [0, 0, 1, 1])


def _copies(poses, jitter=0.0):
    """An L-shaped object (not symmetric) copied at poses, instance ids 1.., plus a floor (id 0)."""
    obj = np.array([[0, 0, 0], [0.2, 0, 0], [0, 0.1, 0], [0, 0, 0.05]], np.float64)
    obj_faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1]])
    positions = [np.array([[-1, 0, -1], [1, 0, -1], [0, 0, 1]], np.float64)]
    faces, ids, uvs = [np.array([[0, 1, 2]])], [0], [np.zeros((3, 2))]
    for k, T in enumerate(poses, 1):
        positions.append(obj @ T[:3, :3].T + T[:3, 3] + jitter * k)
        faces.append(obj_faces + sum(len(p) for p in positions[:-1]))
        ids += [k] * 3
        uvs.append(np.linspace(0, 1, 8).reshape(4, 2))
    return Mesh(
        np.concatenate(positions).astype(np.float32),
        np.concatenate(faces).astype(np.int32),
        np.concatenate(uvs).astype(np.float32),
        np.array(ids, np.int32),
    )


def _pose(angle, t):
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T[:3, 3] = t
    return T


def test_duplicates_are_found_from_their_poses_and_checked():
    poses = [_pose(0.3, [0.1, 0, 0.2]), _pose(2.0, [-0.4, 0.05, 0.1]), _pose(-1.1, [0.3, 0, -0.3])]
    entries = [{"instance_id": k, "T": T} for k, T in enumerate(poses, 1)]
    mesh = _copies(poses)
    found = find_duplicates(mesh, entries, np.ones(len(mesh.faces), bool), tolerance=1e-5)
    assert [c.instance_id for c in found.copies] == [1, 2, 3]
    assert np.allclose(found.prototype.positions, [[0, 0, 0], [0.2, 0, 0], [0, 0.1, 0], [0, 0, 0.05]], atol=1e-7)
    assert np.array_equal(found.face_mask(len(mesh.faces)), mesh.instance_ids > 0)
    # a copy that is not where its pose says is not instanced
    moved = _copies(poses, jitter=1e-3)
    found = find_duplicates(moved, entries, np.ones(len(moved.faces), bool), tolerance=1e-5)
    assert [c.instance_id for c in found.copies] == [1]
    # nor is one with a face that must stay plain (an emitter)
    eligible = np.ones(len(mesh.faces), bool)
    eligible[np.flatnonzero(mesh.instance_ids == 2)[0]] = False
    assert [c.instance_id for c in find_duplicates(mesh, entries, eligible, 1e-5).copies] == [1, 3]


def test_poses_must_be_rigid_transforms():
    scaled = np.diag([2.0, 2.0, 2.0, 1.0])
    with pytest.raises(SceneError, match="T_obj2world"):
        validate_poses({"instances": [{"instance_id": 1, "T_obj2world": scaled.tolist()}]}, "poses.json")
    assert (
        validate_poses(
            {"instances": [{"instance_id": 1, "registered": False, "T_obj2world": np.eye(4).tolist()}]}, "poses.json"
        )
        == []
    )
