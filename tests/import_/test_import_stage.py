"""invrender import: textured OBJ files + a lat-long sky + COLMAP cameras -> a v2 scene directory.

Checked against the files themselves (textures used as the atlas are the decoded PNG times Kd;
a tiled texture baked into its own atlas holds only the texture's colours; constant materials,
Ns and Ke arrive as MILO's maps; the sky keeps its light), against bad inputs, and, in
test_import_mitsuba.py, against Mitsuba rendering the same files."""

import json

import numpy as np
import pytest
from objscene import write_room

from invrender.cli import main
from invrender.scene.atlas import texel_index
from invrender.scene.cubemap import cube_texel_solid_angles, latlong_directions, latlong_solid_angles
from invrender.scene.format import load_scene
from invrender.scene.images import read_image, write_exr
from invrender.scene.mtl import phong_to_beckmann


def write_sky(path, radiance):
    write_exr(path, radiance(latlong_directions(128, 64)))


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    root = tmp_path_factory.mktemp("import")
    files = write_room(root / "files", write_sky)
    out = root / "scene"
    assert (
        main(["import", str(files), "--out", str(out), "--environment", str(files / "sky.exr"), "--cube-size", "16"])
        == 0
    )
    return files, out, load_scene(out)


def test_objects_and_material_sets_follow_the_files(imported):
    files, out, scene = imported
    names = {obj.name: obj.material for obj in scene.objects}
    assert names == {"room.walls": "walls", "room.floor": "room.floor-floor", "box": "box", "lamp": "lamp"}
    assert all(obj.emission_sides == "one" for obj in scene.objects)
    assert all(np.array_equal(obj.transform, np.eye(4)) for obj in scene.objects)
    assert len(scene.cameras) == 1 and scene.cameras[0].name == "view.png"


def test_textures_in_unit_uvs_are_the_atlas_and_tiled_ones_are_baked(imported):
    files, out, scene = imported
    sets = scene.packing.unpack_atlas(scene.maps)
    np.testing.assert_array_equal(sets["walls"].kd, read_image(files / "walls.png"))  # Kd 1: the decoded PNG
    # The floor's UVs tile 4 times (u = x + 2, v = 2 - z): at points of the floor away from the
    # checker's edges, the baked atlas must hold what the tiled texture shows there.
    floor_texture = read_image(files / "floor.png")
    floor = next(obj for obj in scene.objects if obj.name == "room.floor")
    atlas = sets["room.floor-floor"].kd
    x, z = np.meshgrid(np.linspace(-1.93, 1.93, 61), np.linspace(-1.93, 1.93, 61))
    points = np.stack([x.ravel(), np.zeros(x.size), z.ravel()], -1)
    u, v = (points[:, 0] + 2) % 1, (2 - points[:, 2]) % 1
    # (a baked texel is 1/16 m wide, a checker block 1/4 m: keep points a texel clear of an edge)
    away = (np.abs((u * 4 + 0.5) % 1 - 0.5) > 0.3) & (np.abs((v * 4 + 0.5) % 1 - 0.5) > 0.3)
    expected = floor_texture[np.minimum(np.floor((1 - v) * 8).astype(int), 7), np.floor(u * 8).astype(int)]
    found = atlas[texel_index(surface_uvs(floor.mesh, points), atlas.shape)]
    assert away.sum() > 300
    np.testing.assert_array_equal(found[away], expected[away])


def surface_uvs(mesh, points):
    """The mesh's UVs at points on it (the triangle containing each point, barycentric)."""
    corners = np.asarray(mesh.positions, np.float64)[mesh.faces]
    out = np.full((len(points), 2), np.nan)
    for face, (a, b, c) in enumerate(corners):
        m = np.stack([b - a, c - a], 1)
        weights, *_ = np.linalg.lstsq(m, (points - a).T, rcond=None)
        w1, w2 = weights
        inside = (w1 >= -1e-9) & (w2 >= -1e-9) & (w1 + w2 <= 1 + 1e-9)
        uv = np.asarray(mesh.uvs, np.float64)[mesh.faces[face]]
        out[inside] = ((1 - w1 - w2)[:, None] * uv[0] + w1[:, None] * uv[1] + w2[:, None] * uv[2])[inside]
    assert np.isfinite(out).all()
    return out


def test_constant_materials_and_emission(imported):
    _, _, scene = imported
    sets = scene.packing.unpack_atlas(scene.maps)
    np.testing.assert_allclose(sets["box"].kd[0, 0], [0.7, 0.3, 0.2], rtol=1e-6)
    np.testing.assert_allclose(sets["lamp"].ke[0, 0], [6, 6, 5])
    assert sets["lamp"].kd.max() == 0 and sets["walls"].ke.max() == 0
    assert sets["box"].ka[0, 0] == pytest.approx(1.0)  # no Ns: a rough surface
    assert phong_to_beckmann(98.0) == pytest.approx(0.02)


def test_the_sky_keeps_its_light(imported):
    files, _, scene = imported
    latlong = read_image(files / "sky.exr")
    total_in = (latlong * latlong_solid_angles(128, 64)[..., None]).sum(axis=(0, 1))
    n = scene.maps.kg.shape[1]
    total_out = (scene.maps.kg * cube_texel_solid_angles(n)[None, ..., None]).sum(axis=(0, 1, 2))
    np.testing.assert_allclose(total_out, total_in, rtol=1e-5)


def test_a_window_material_opens_onto_the_sky(tmp_path):
    files = write_room(tmp_path / "files", write_sky)
    out = tmp_path / "scene"
    assert main(["import", str(files), "--out", str(out), "--window", "box"]) == 0
    sets = load_scene(out).packing.unpack_atlas(load_scene(out).maps)
    assert sets["box"].kw.min() == 1 and sets["box"].kd.max() == 0 and sets["box"].ks.max() == 0


@pytest.mark.parametrize(
    "breakage, field",
    [
        (
            lambda f: (f / "room.mtl").write_text(
                (f / "room.mtl").read_text().replace("newmtl floor", "newmtl parquet")
            ),
            "usemtl floor",
        ),
        (lambda f: (f / "walls.png").unlink(), "map_Kd"),
        (lambda f: (f / "room.mtl").write_text((f / "room.mtl").read_text().replace("Kd 0.7 0.3 0.2", "Kd red")), "Kd"),
        (lambda f: (f / "box.obj").write_text((f / "box.obj").read_text() + "f 1/1 2/2 99/3\n"), "face"),
    ],
)
def test_bad_files_stop_with_one_message_and_write_nothing(tmp_path, capsys, breakage, field):
    files = write_room(tmp_path / "files", write_sky)
    breakage(files)
    out = tmp_path / "scene"
    assert main(["import", str(files), "--out", str(out)]) == 2
    assert field in capsys.readouterr().err
    assert not out.exists()


def test_the_summary_is_logged_and_the_scene_is_version_2(imported):
    _, out, _ = imported
    assert json.loads((out / "scene.json").read_text())["version"] == 2
