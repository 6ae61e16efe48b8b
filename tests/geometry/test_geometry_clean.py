"""Loading and cleaning: refusals name the file and the field; cleaning reports what it removed."""

import numpy as np
import plyfile
import pymeshlab
import pytest

from invrender.geometry.clean import clean_mesh, input_kind, load_geometry
from invrender.scene.types import SceneError


def write_ply(path, positions, faces=None, normals=None):
    fields = [(c, "f4") for c in "xyz"] + ([(c, "f4") for c in ("nx", "ny", "nz")] if normals is not None else [])
    vertex = np.empty(len(positions), dtype=fields)
    for i, c in enumerate("xyz"):
        vertex[c] = np.asarray(positions)[:, i]
        if normals is not None:
            vertex["n" + c] = np.asarray(normals)[:, i]
    elements = [plyfile.PlyElement.describe(vertex, "vertex")]
    if faces is not None:
        face = np.empty(len(faces), dtype=[("vertex_indices", "i4", (3,))])
        face["vertex_indices"] = faces
        elements.append(plyfile.PlyElement.describe(face, "face"))
    plyfile.PlyData(elements).write(str(path))
    return path


TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])


def test_nan_vertex_is_refused(tmp_path):
    """pymeshlab would drop the NaN vertex and its face without a word; we refuse the file."""
    positions = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [np.nan, 1, 0]]
    path = write_ply(tmp_path / "nan.ply", positions, TRIANGLES)
    with pytest.raises(SceneError) as error:
        load_geometry(path)
    assert error.value.file == str(path) and error.value.field == "vertex positions"
    assert error.value.expected.startswith("finite numbers") and "vertex 3" in error.value.expected


def test_inf_vertex_in_obj_is_refused(tmp_path):
    path = tmp_path / "inf.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 inf 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match="vertex positions: expected finite numbers"):
        load_geometry(path)


def test_points_without_faces_or_normals_are_refused(tmp_path):
    path = write_ply(tmp_path / "points.ply", np.random.default_rng(0).random((50, 3)))
    with pytest.raises(SceneError) as error:
        load_geometry(path)
    assert (error.value.file, error.value.field) == (str(path), "faces")
    assert error.value.expected.startswith("a mesh with faces, or a point cloud with normals")


@pytest.mark.parametrize(
    "name, content, field",
    [
        ("empty.ply", b"", "(file)"),
        ("empty.obj", b"", "(file)"),
        ("garbage.ply", b"hello\n", "(file)"),
        ("mesh.stl", b"solid x\n", "(file name)"),
    ],
)
def test_empty_unreadable_and_unknown_files_are_refused(tmp_path, name, content, field):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SceneError) as error:
        load_geometry(path)
    assert (error.value.file, error.value.field) == (str(path), field)


def test_missing_file_is_refused(tmp_path):
    with pytest.raises(SceneError, match=r"missing\.ply: \(file\)"):
        load_geometry(tmp_path / "missing.ply")


def test_zero_normals_are_refused(tmp_path):
    normals = np.tile([0.0, 0.0, 1.0], (10, 1))
    normals[4] = 0
    path = write_ply(tmp_path / "cloud.ply", np.random.default_rng(0).random((10, 3)), normals=normals)
    with pytest.raises(SceneError, match="vertex normals: expected finite non-zero normals.*point 4"):
        load_geometry(path)


def test_point_cloud_and_mesh_kinds(tmp_path):
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(20, 3))
    cloud = load_geometry(write_ply(tmp_path / "cloud.ply", rng.random((20, 3)), normals=normals))
    assert input_kind(cloud) == "point_cloud" and cloud.current_mesh().vertex_number() == 20
    stored = cloud.current_mesh().vertex_normal_matrix()
    assert np.allclose(stored, normals / np.linalg.norm(normals, axis=1, keepdims=True), atol=1e-6)
    obj = tmp_path / "cloud.obj"  # pymeshlab would ignore the vn of a face-less OBJ
    obj.write_text("".join(f"v {p[0]} {p[1]} {p[2]}\n" for p in rng.random((5, 3))) + "vn 0 1 0\n" * 5)
    assert input_kind(load_geometry(obj)) == "point_cloud"
    quad = tmp_path / "quad.obj"
    quad.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    ms = load_geometry(quad)
    assert input_kind(ms) == "mesh" and ms.current_mesh().face_number() == 2


def test_clean_mesh_reports_what_it_removed():
    """A closed unit sphere plus: 10 duplicated vertices (copies of vertices, unused), 5
    duplicated faces, a face whose corners coincide, a zero-area face, 2 small extra faces on one edge
    (non-manifold), a small far triangle (an island 1/1000 of the diagonal) and 3 unreferenced
    vertices. Cleaning gives back the closed sphere."""
    ms = pymeshlab.MeshSet()
    ms.create_sphere(subdiv=3)
    v, f = ms.current_mesh().vertex_matrix(), ms.current_mesh().face_matrix()
    n, nf = len(v), len(f)
    a, b = f[0, 0], f[0, 1]
    middle = 0.5 * (v[a] + v[b])
    fin_tips = [middle * 1.02, middle * 0.98]  # 2% of the radius out and in: crumbs, not surface
    extra_v = np.vstack(
        [
            v[:10],  # n .. n+9: duplicates of 0..9
            [[5, 5, 5], [5, 5, 5.01], [5, 5.01, 5]],  # n+10..n+12: the island
            fin_tips,  # n+13, n+14: small fins on an edge
            [[9, 9, 9], [8, 8, 8], [7, 7, 7]],  # n+15..n+17: unreferenced
            [[0.1, 0.2, 0.3]] * 3,  # n+18..n+20: coincident corners
            [[0.1, 0.1, 0.1], [0.2, 0.2, 0.2], [0.4, 0.4, 0.4]],  # n+21..n+23: collinear corners
        ]
    )
    extra_f = np.vstack(
        [
            f[:5],  # duplicate faces
            [[n + 10, n + 11, n + 12]],  # island
            [[a, b, n + 13], [a, b, n + 14]],  # two more faces on edge (a, b)
            [[n + 18, n + 19, n + 20]],  # one vertex thrice after merging
            [[n + 21, n + 22, n + 23]],  # zero area
        ]
    )
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.vstack([v, extra_v]), np.vstack([f, extra_f])))
    report = clean_mesh(ms, min_island_fraction=0.01, min_island_faces=0)
    print(report)
    mesh = ms.current_mesh()
    assert report["duplicate_vertices"]["vertices"] == 10 + 2  # the copies, and two of the coincident corners
    assert report["duplicate_faces"]["faces"] == 5
    # merging the coincident corners left a face with one vertex thrice: removed on the way
    assert report["duplicate_vertices"]["faces"] == 1
    assert report["zero_area_faces"]["faces"] == 1
    assert report["non_manifold_edges"]["faces"] == 2  # the fins: pymeshlab removes the smaller faces
    assert report["small_islands_by_size"]["faces"] == 1
    # 3 unreferenced from the start, 3 of the island, 2 fin tips, 1 coincident and 3 collinear corners
    assert report["unreferenced_vertices"]["vertices"] == 3 + 3 + 2 + 1 + 3
    total = sum(step["faces"] for step in report.values())
    assert mesh.face_number() == nf + len(extra_f) - total == nf
    assert mesh.vertex_number() == n
    topology = ms.get_topological_measures()
    assert topology["is_mesh_two_manifold"] and topology["boundary_edges"] == 0
    assert topology["unreferenced_vertices"] == 0
