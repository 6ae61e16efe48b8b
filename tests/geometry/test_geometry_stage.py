"""The geometry stage end to end: point cloud -> mesh.ply + atlas.npz + geometry.json, the atlas
looked up through the mesh UVs, refusals that leave nothing behind, and the CLI."""

import json

import numpy as np
import plyfile
import pymeshlab
import pytest
from rooms import ROOM, sample_room

from invrender.cli import main
from invrender.geometry.stage import run
from invrender.scene.atlas import AtlasTexels, dilate, texel_index
from invrender.scene.atomic import MARKER
from invrender.scene.mesh_io import read_mesh
from invrender.scene.types import SceneError


def room_cloud(path, n, rng, noise=0.01):
    """A PLY point cloud on the sides of a 4 x 3 x 5 m box, inward normals, Gaussian noise."""
    points, normals = sample_room(n, rng)
    points += rng.normal(scale=noise, size=points.shape)
    vertex = np.empty(n, dtype=[(c, "f4") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for i, c in enumerate("xyz"):
        vertex[c], vertex["n" + c] = points[:, i], normals[:, i]
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex")]).write(str(path))
    return path


def sphere_mesh(path, subdiv=3):
    ms = pymeshlab.MeshSet()
    ms.create_sphere(subdiv=subdiv)
    ms.save_current_mesh(str(path), save_vertex_normal=False, save_vertex_color=False)
    return path


@pytest.fixture(scope="module")
def stage_output(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("geometry")
    source = room_cloud(tmp / "room.ply", 15_000, np.random.default_rng(0))
    out = tmp / "out"
    report = run(source, out, target_faces=5000, atlas_resolution=512, poisson_depth=7, threads=1, progress=False)
    print(f"\nstage timings: {report['timings_s']}")
    return out, report


def test_stage_writes_its_three_files(stage_output):
    out, report = stage_output
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "atlas.npz", "geometry.json", "mesh.ply"]
    assert json.loads((out / "geometry.json").read_text()) == report
    assert not list(out.parent.glob(".out.tmp-*"))
    mesh = read_mesh(out / "mesh.ply")
    assert report["input_kind"] == "point_cloud"
    assert abs(report["simplification"]["faces_after"] - 5000) <= 250 == 0.05 * 5000
    assert len(mesh.faces) == report["mesh"]["faces"] == report["simplification"]["faces_after"]
    assert mesh.instance_ids is not None and not mesh.instance_ids.any()
    assert mesh.uvs.min() >= 0 and mesh.uvs.max() <= 1
    # meters, as given: the box's 4 x 3 x 5 m extent within the noise and Poisson's smoothing
    assert np.allclose(mesh.positions.min(0), 0, atol=0.05)
    assert np.allclose(mesh.positions.max(0), ROOM, atol=0.05)


def test_atlas_lookup_through_the_mesh_uvs(stage_output):
    """Random points on random triangles: the texel read through the interpolated UV (column
    floor(u W), row floor((1 - v) H)) stores a 3D point within one texel size (1 / texel density)
    of the point. A few points fall in a texel whose centre lies outside every triangle (chart
    borders); grown by `dilate` over the padding, those are within 1.5 texel sizes."""
    out, report = stage_output
    mesh = read_mesh(out / "mesh.ply")
    texels = AtlasTexels.load(out / "atlas.npz")
    assert texels.shape == (report["atlas"]["height"], report["atlas"]["width"])
    rng = np.random.default_rng(1)
    n = 20_000
    tri = rng.integers(len(mesh.faces), size=n)
    weights = rng.dirichlet([1, 1, 1], size=n)
    points = np.einsum("nk,nkc->nc", weights, mesh.positions[mesh.faces[tri]].astype(np.float64))
    uvs = np.einsum("nk,nkc->nc", weights, mesh.uvs[mesh.faces[tri]].astype(np.float64))
    row, col = texel_index(uvs, texels.shape)
    assert np.array_equal(col, np.floor(uvs[:, 0] * texels.shape[1]).astype(int))
    assert np.array_equal(row, np.floor((1 - uvs[:, 1]) * texels.shape[0]).astype(int))
    texel_size = 1.0 / report["atlas"]["texel_density_per_m"]
    covered = texels.mask[row, col]
    error = np.linalg.norm(texels.position[row, col] - points, axis=1) / texel_size
    same = (texels.triangle[row, col] == tri).mean()
    print(
        f"\ncovered {100 * covered.mean():.2f}%, same triangle {100 * same:.1f}%, "
        f"error in texel sizes: median {np.median(error[covered]):.2f}, max {error[covered].max():.2f}"
    )
    assert covered.mean() > 0.98
    assert error[covered].max() < 1.0
    grown, grown_mask = dilate(texels.position, texels.mask, report["atlas"]["padding"])
    assert grown_mask[row, col].all()
    assert (np.linalg.norm(grown[row, col] - points, axis=1) / texel_size).max() < 1.5


def test_report_is_plausible(stage_output):
    out, report = stage_output
    atlas = report["atlas"]
    # the density is measured on the UVs, the utilisation on the rasterised texels: they agree
    implied = np.sqrt(atlas["covered_texels"] / report["mesh"]["area_m2"])
    print(
        f"\nutilisation {atlas['utilisation']:.3f}, density {atlas['texel_density_per_m']:.1f} /m "
        f"(covered texels / area implies {implied:.1f})"
    )
    assert 0.4 < atlas["utilisation"] <= 1.0
    assert atlas["utilisation"] == pytest.approx(atlas["covered_texels"] / (512 * 512))
    assert atlas["texel_density_per_m"] == pytest.approx(implied, rel=0.1)
    assert atlas["texel_size_m"] == pytest.approx(1 / atlas["texel_density_per_m"])
    assert (atlas["width"], atlas["height"]) == (512, 512)
    assert report["mesh"]["area_m2"] == pytest.approx(2 * (4 * 3 + 4 * 5 + 3 * 5), rel=0.05)
    assert report["reconstruction"]["points"] == 15_000 and report["input"]["faces"] == 0
    assert set(report["cleaning"]) >= {
        "duplicate_vertices",
        "duplicate_faces",
        "zero_area_faces",
        "non_manifold_edges",
        "unreferenced_vertices",
    }


@pytest.mark.parametrize("kind", ["nan", "bare points", "empty"])
def test_refusals_leave_no_output(tmp_path, kind):
    source = tmp_path / "bad.ply"
    if kind == "empty":
        source.write_bytes(b"")
        field = "(file)"
    else:
        positions = np.random.default_rng(0).random((4, 3)).astype(np.float32)
        vertex = np.empty(4, dtype=[(c, "f4") for c in "xyz"])
        if kind == "nan":
            positions[2, 1] = np.nan
        for i, c in enumerate("xyz"):
            vertex[c] = positions[:, i]
        elements = [plyfile.PlyElement.describe(vertex, "vertex")]
        if kind == "nan":
            face = np.array([([0, 1, 2],), ([0, 2, 3],)], dtype=[("vertex_indices", "i4", (3,))])
            elements.append(plyfile.PlyElement.describe(face, "face"))
        plyfile.PlyData(elements).write(str(source))
        field = "vertex positions" if kind == "nan" else "faces"
    out = tmp_path / "results" / "geometry"
    with pytest.raises(SceneError) as error:
        run(source, out, progress=False)
    assert (error.value.file, error.value.field) == (str(source), field)
    assert not out.exists() and not (tmp_path / "results").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.ply"]


def test_all_degenerate_mesh_is_refused_after_cleaning(tmp_path):
    source = tmp_path / "flat.obj"
    source.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")  # one zero-area triangle
    with pytest.raises(SceneError) as error:
        run(source, tmp_path / "out", progress=False)
    assert (error.value.file, error.value.field) == (str(source), "faces")
    assert "zero_area_faces" in error.value.expected
    assert not (tmp_path / "out").exists()


def test_failure_midway_keeps_the_previous_output(tmp_path, monkeypatch):
    """An error after work started (here in the rasteriser) leaves the old directory as it was."""
    import invrender.geometry.stage as stage

    source = sphere_mesh(tmp_path / "sphere.ply")
    out = tmp_path / "out"
    out.mkdir()
    (out / MARKER).write_text("geometry\n")  # an earlier geometry output, which --out may replace
    (out / "old.txt").write_text("old")

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(stage, "rasterize_atlas", broken)
    with pytest.raises(RuntimeError):
        run(source, out, atlas_resolution=64, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "sphere.ply"]
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "old.txt"]


def test_cli_end_to_end_on_a_small_mesh(tmp_path, caplog):
    source = sphere_mesh(tmp_path / "sphere.ply", subdiv=4)  # 5120 faces, radius 1 m
    out = tmp_path / "geometry"
    caplog.set_level("INFO")  # under pytest the root logger has handlers, so main's --log file stays empty
    code = main(
        [
            "geometry",
            str(source),
            "--out",
            str(out),
            "--target-faces",
            "1000",
            "--texels-per-meter",
            "40",
            "--padding",
            "3",
        ]
    )
    assert code == 0
    report = json.loads((out / "geometry.json").read_text())
    assert report["input_kind"] == "mesh" and report["input"]["faces"] == 5120
    assert abs(report["mesh"]["faces"] - 1000) <= 50
    assert report["atlas"]["requested"] == {"texels_per_meter": 40.0} and report["atlas"]["padding"] == 3
    assert report["atlas"]["texel_density_per_m"] == pytest.approx(40, rel=0.1)
    mesh = read_mesh(out / "mesh.ply")
    assert len(mesh.faces) == report["mesh"]["faces"]
    assert np.allclose(np.linalg.norm(mesh.positions, axis=1), 1.0, atol=0.02)
    assert AtlasTexels.load(out / "atlas.npz").shape == (report["atlas"]["height"], report["atlas"]["width"])
    assert "utilisation" in caplog.text and "texels/m" in caplog.text

    # bad input through the CLI: exit code 2, the error in the log, no output
    bad = tmp_path / "empty.obj"
    bad.write_text("")
    assert main(["geometry", str(bad), "--out", str(tmp_path / "nothing")]) == 2
    assert f"{bad}: (file): expected" in caplog.text
    assert not (tmp_path / "nothing").exists()


def test_two_triangle_lamps_survive_cleaning(tmp_path):
    """Issue 11: a captured room whose two 0.6 m ceiling panels are separate pieces of two
    triangles each (as lamps often are). Size relative to the room decides what is a crumb, so both
    panels come out of the geometry stage, and a crumb 2 cm across does not."""
    from invrender.scene.mesh_io import read_mesh, write_ply
    from invrender.scene.types import Mesh

    positions, faces = _room_with_panels()
    source = tmp_path / "room.ply"
    write_ply(source, Mesh(positions, faces, np.zeros((len(positions), 2), np.float32)))
    out = tmp_path / "geometry"
    report = run(source, out, target_faces=5000, atlas_resolution=64, progress=False)
    mesh = read_mesh(out / "mesh.ply")
    for x0 in (1.0, 2.6):  # each panel: faces 2 cm under the ceiling, where the panel was
        centres = mesh.positions[mesh.faces].mean(axis=1)
        on_panel = (np.abs(centres[:, 1] - 2.98) < 1e-3) & (centres[:, 0] > x0) & (centres[:, 0] < x0 + 0.6)
        assert on_panel.sum() >= 2, (x0, report)
    assert not np.any(np.abs(mesh.positions[:, 1] - 1.5) < 1e-3), "the 2 cm crumb in mid-air should be removed"


def _room_with_panels():
    """A closed 4 x 3 x 5 m box (12 triangles), two 0.6 x 0.6 m panels 2 cm below the ceiling
    facing down (2 triangles each), and a 2 cm crumb floating in the middle of the room."""
    w, h, d = 4.0, 3.0, 5.0
    corners = np.array([[x, y, z] for x in (0, w) for y in (0, h) for z in (0, d)], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [tri for a, b, c, e in quads for tri in ((a, b, c), (a, c, e))]
    positions = list(corners)
    for x0 in (1.0, 2.6):
        base = len(positions)
        positions += [[x0, 2.98, 2.0], [x0 + 0.6, 2.98, 2.0], [x0 + 0.6, 2.98, 2.6], [x0, 2.98, 2.6]]
        faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    base = len(positions)
    positions += [[2.0, 1.5, 2.5], [2.02, 1.5, 2.5], [2.0, 1.5, 2.52]]
    faces += [(base, base + 1, base + 2)]
    return np.asarray(positions, np.float32), np.asarray(faces, np.int32)
