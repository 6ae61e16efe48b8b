"""Mesh I/O: PLY and OBJ readers, the PLY writer, and the errors they raise."""

import numpy as np
import plyfile
import pytest

from invrender.scene import Mesh, SceneError
from invrender.scene.mesh_io import read_mesh, write_ply


def quad_mesh(instance=True):
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], np.float32)
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 1, 4]], np.int32)
    ids = np.array([1, 1, 2], np.int32) if instance else None
    return Mesh(positions=positions, faces=faces, uvs=uvs, instance_ids=ids)


def assert_same(a: Mesh, b: Mesh):
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.uvs, b.uvs)
    if a.instance_ids is None:
        assert b.instance_ids is None or not b.instance_ids.any()
    else:
        np.testing.assert_array_equal(a.instance_ids, b.instance_ids)


def test_ply_roundtrip(tmp_path):
    mesh = quad_mesh()
    write_ply(tmp_path / "m.ply", mesh)
    ply = plyfile.PlyData.read(str(tmp_path / "m.ply"))
    assert not ply.text and ply.byte_order == "<"
    assert [p.name for p in ply["vertex"].properties] == ["x", "y", "z", "s", "t"]
    assert [p.name for p in ply["face"].properties] == ["vertex_indices", "instance_id"]
    back = read_mesh(tmp_path / "m.ply")
    assert back.positions.dtype == np.float32 and back.faces.dtype == np.int32
    assert_same(mesh, back)


def test_ply_roundtrip_without_instances_and_big(tmp_path):
    rng = np.random.default_rng(1)
    n = 5000
    mesh = Mesh(
        positions=rng.random((n, 3), dtype=np.float32),
        faces=rng.integers(0, n, (2 * n, 3)).astype(np.int32),
        uvs=rng.random((n, 2), dtype=np.float32),
    )
    write_ply(tmp_path / "big.ply", mesh)
    assert_same(mesh, read_mesh(tmp_path / "big.ply"))


def write_ascii_ply(path, header_props, vertices, faces_lines, face_props="property list uchar int vertex_indices"):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}"]
    lines += [f"property float {p}" for p in header_props]
    lines += [f"element face {len(faces_lines)}", face_props, "end_header"]
    lines += [" ".join(map(str, v)) for v in vertices] + faces_lines
    path.write_text("\n".join(lines) + "\n")


def test_ply_uv_names_and_polygons(tmp_path):
    verts = [(0, 0, 0, 0, 0), (1, 0, 0, 1, 0), (1, 1, 0, 1, 1), (0, 1, 0, 0, 1)]
    write_ascii_ply(tmp_path / "uv.ply", ["x", "y", "z", "u", "v"], verts, ["4 0 1 2 3"])
    mesh = read_mesh(tmp_path / "uv.ply")
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(mesh.uvs[2], [1, 1])
    write_ascii_ply(tmp_path / "tex.ply", ["x", "y", "z", "texture_u", "texture_v"], verts, ["3 0 1 2"])
    np.testing.assert_array_equal(read_mesh(tmp_path / "tex.ply").uvs[:, 0], [0, 1, 1, 0])


def test_ply_wedge_texcoords_split(tmp_path):
    # MeshLab style: UVs per face corner. Vertex 0 has two different UVs -> split.
    verts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    faces = ["3 0 1 2 6 0 0 1 0 1 1", "3 0 2 3 6 0.5 0.5 1 1 0 1"]
    write_ascii_ply(
        tmp_path / "w.ply",
        ["x", "y", "z"],
        verts,
        faces,
        face_props="property list uchar int vertex_indices\nproperty list uchar float texcoord",
    )
    mesh = read_mesh(tmp_path / "w.ply")
    assert len(mesh.positions) == 5 and len(mesh.faces) == 2
    corners = mesh.uvs[mesh.faces]
    np.testing.assert_array_equal(corners[0], [[0, 0], [1, 0], [1, 1]])
    np.testing.assert_array_equal(corners[1], [[0.5, 0.5], [1, 1], [0, 1]])
    np.testing.assert_array_equal(mesh.positions[mesh.faces[1]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]])


OBJ = """# a quad with a seam: vertex 1 has two UVs
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.25 0.25
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
f 1/5 3/3 -1/4
"""


def test_obj_split_and_fan(tmp_path):
    (tmp_path / "q.obj").write_text(OBJ)
    mesh = read_mesh(tmp_path / "q.obj")
    assert len(mesh.faces) == 3
    assert len(mesh.positions) == 5  # 4 (v, vt) pairs of the quad + (1, 5)
    tri_pos = mesh.positions[mesh.faces]
    tri_uv = mesh.uvs[mesh.faces]
    np.testing.assert_array_equal(tri_pos[0], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    np.testing.assert_array_equal(tri_pos[1], [[0, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_array_equal(tri_uv[1], [[0, 0], [1, 1], [0, 1]])
    np.testing.assert_array_equal(tri_uv[2], [[0.25, 0.25], [1, 1], [0, 1]])
    # OBJ -> PLY -> read gives the same triangles
    write_ply(tmp_path / "q.ply", mesh)
    assert_same(mesh, read_mesh(tmp_path / "q.ply"))


def test_mesh_without_uvs(tmp_path):
    (tmp_path / "n.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\n")
    with pytest.raises(SceneError) as err:
        read_mesh(tmp_path / "n.obj")
    assert "n.obj" in str(err.value) and "vertex s,t (texture coordinates)" in str(err.value)
    mesh = read_mesh(tmp_path / "n.obj", require_uvs=False)
    assert mesh.uvs is None and len(mesh.positions) == 3
    write_ascii_ply(tmp_path / "n.ply", ["x", "y", "z"], [(0, 0, 0), (1, 0, 0), (0, 1, 0)], ["3 0 1 2"])
    with pytest.raises(SceneError, match=r"n\.ply: vertex s,t \(texture coordinates\)"):
        read_mesh(tmp_path / "n.ply")
    assert read_mesh(tmp_path / "n.ply", require_uvs=False).uvs is None


def test_nan_vertex(tmp_path):
    mesh = quad_mesh()
    mesh.positions[3, 1] = np.nan
    write_ply(tmp_path / "nan.ply", mesh)
    with pytest.raises(SceneError, match=r"nan\.ply: vertex 3 x,y,z: expected finite"):
        read_mesh(tmp_path / "nan.ply")


def test_no_faces(tmp_path):
    write_ascii_ply(tmp_path / "e.ply", ["x", "y", "z", "s", "t"], [(0, 0, 0, 0, 0)], [])
    with pytest.raises(SceneError, match=r"e\.ply: face: expected at least one face"):
        read_mesh(tmp_path / "e.ply")
    (tmp_path / "e.obj").write_text("v 0 0 0\nvt 0 0\n")
    with pytest.raises(SceneError, match=r"e\.obj: f: expected at least one face"):
        read_mesh(tmp_path / "e.obj")


def test_face_index_out_of_range(tmp_path):
    mesh = quad_mesh()
    mesh.faces[2, 1] = 99
    write_ply(tmp_path / "oor.ply", mesh)
    with pytest.raises(SceneError, match=r"oor\.ply: face 2 vertex_indices: expected indices in \[0, 5\)"):
        read_mesh(tmp_path / "oor.ply")
    (tmp_path / "oor.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 7/1\n")
    with pytest.raises(SceneError, match=r"oor\.obj: face 0 v: expected indices in \[1, 3\]"):
        read_mesh(tmp_path / "oor.obj")


def test_not_a_mesh(tmp_path):
    (tmp_path / "x.ply").write_text("garbage")
    with pytest.raises(SceneError, match=r"x\.ply"):
        read_mesh(tmp_path / "x.ply")
    with pytest.raises(SceneError, match=r"missing\.ply"):
        read_mesh(tmp_path / "missing.ply")
