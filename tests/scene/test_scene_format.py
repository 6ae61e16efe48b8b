"""The scene directory: round trip, and one SceneError naming file and field per bad input."""

import json

import numpy as np
import pytest

from invrender.scene import Camera, Maps, Mesh, Scene, SceneError
from invrender.scene.format import SCHEMA_PATH, load_scene, read_scene_json, write_scene
from invrender.scene.images import read_image, write_exr


def make_scene(cameras=True, size=(8, 12), cube=4):
    rng = np.random.default_rng(7)
    h, w = size
    maps = Maps(
        kd=rng.random((h, w, 3), dtype=np.float32),
        ks=rng.random((h, w, 3), dtype=np.float32) * 0.1,
        ka=rng.uniform(1e-3, 1, (h, w)).astype(np.float32),
        ke=rng.random((h, w, 3), dtype=np.float32) * 5,
        kw=rng.random((h, w), dtype=np.float32),
        kg=rng.random((6, cube, cube, 3), dtype=np.float32) * 10,
    )
    mesh = Mesh(
        positions=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32),
        faces=np.array([[0, 1, 2], [0, 2, 3]], np.int32),
        uvs=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32),
        instance_ids=np.array([0, 3], np.int32),
    )
    cams = []
    if cameras:
        cams = [
            Camera(
                "v1.png", "PINHOLE", 32, 24, np.array([30.0, 30.0, 16.0, 12.0]), np.eye(3), np.array([0.0, 0.0, 2.0])
            ),
            Camera(
                "v0.png",
                "OPENCV",
                32,
                24,
                np.array([30.0, 31.0, 16.5, 12.5, 0.01, 0, 0, 0]),
                np.diag([1.0, -1.0, -1.0]),
                np.array([0.5, 0.0, 3.0]),
            ),
        ]
    return Scene(mesh=mesh, maps=maps, cameras=cams)


@pytest.fixture
def scene_dir(tmp_path):
    write_scene(tmp_path / "scene", make_scene(), metadata={"stage": "test", "seed": 1})
    return tmp_path / "scene"


def edit_json(directory, fn):
    path = directory / "scene.json"
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def test_roundtrip(scene_dir):
    ref = make_scene()
    doc = read_scene_json(scene_dir)
    assert doc["format"] == "invrender-scene" and doc["version"] == 1 and doc["metadata"]["seed"] == 1
    assert doc["maps"]["kg"] == "maps/kg.exr" and doc["cameras"] == "cameras"
    assert read_image(scene_dir / "maps" / "kg.exr").shape == (24, 4, 3)
    scene = load_scene(scene_dir)
    assert scene.path == scene_dir
    for name in ("kd", "ks", "ka", "ke", "kw", "kg"):
        got, want = getattr(scene.maps, name), getattr(ref.maps, name)
        assert got.shape == want.shape, name
        np.testing.assert_array_equal(got, want)
    # kg faces stacked top to bottom: rows [N, 2N) of the file are face -X
    np.testing.assert_array_equal(read_image(scene_dir / "maps" / "kg.exr")[4:8], ref.maps.kg[1])
    np.testing.assert_array_equal(scene.mesh.positions, ref.mesh.positions)
    np.testing.assert_array_equal(scene.mesh.faces, ref.mesh.faces)
    np.testing.assert_array_equal(scene.mesh.uvs, ref.mesh.uvs)
    np.testing.assert_array_equal(scene.mesh.instance_ids, ref.mesh.instance_ids)
    assert [c.name for c in scene.cameras] == ["v0.png", "v1.png"]
    np.testing.assert_allclose(scene.cameras[0].R, np.diag([1.0, -1.0, -1.0]), atol=1e-12)
    np.testing.assert_allclose(scene.cameras[0].params, ref.cameras[1].params)


def test_no_cameras(tmp_path):
    write_scene(tmp_path / "s", make_scene(cameras=False))
    assert "cameras" not in read_scene_json(tmp_path / "s")
    assert not (tmp_path / "s" / "cameras").exists()
    assert load_scene(tmp_path / "s").cameras == []


def test_overwrite_replaces_whole(scene_dir):
    (scene_dir / "leftover.txt").write_text("old")
    write_scene(scene_dir, make_scene(cameras=False))
    assert not (scene_dir / "leftover.txt").exists() and not (scene_dir / "cameras").exists()
    assert sorted(p.name for p in scene_dir.parent.iterdir()) == ["scene"]


def test_schema_is_draft_2020_12():
    schema = json.loads(SCHEMA_PATH.read_text())
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["$defs"]["v1"]["additionalProperties"] is False
    assert schema["$defs"]["v2"]["additionalProperties"] is False


def one_error(directory) -> str:
    with pytest.raises(SceneError) as err:
        load_scene(directory)
    return str(err.value)


def test_missing_field(scene_dir):
    edit_json(scene_dir, lambda d: d.pop("mesh"))
    msg = one_error(scene_dir)
    assert "scene.json: mesh: expected" in msg and "required" in msg
    edit_json(scene_dir, lambda d: (d.update(mesh="mesh.ply"), d["maps"].pop("kw")))
    assert "scene.json: maps.kw: expected this required field" in one_error(scene_dir)


def test_unknown_top_level_key(scene_dir):
    edit_json(scene_dir, lambda d: d.update(environment="sky.exr"))
    msg = one_error(scene_dir)
    assert "scene.json: environment: expected no such field" in msg


def test_wrong_version_and_path_outside(scene_dir):
    edit_json(scene_dir, lambda d: d.update(version=3))
    assert "scene.json: version: expected one of 1, 2, got 3" in one_error(scene_dir)
    edit_json(scene_dir, lambda d: d.update(version=2))  # a v1 document that says it is v2
    assert "scene.json: maps: expected no such field: allowed fields are cameras, format, kg, materials" in one_error(
        scene_dir
    )
    edit_json(scene_dir, lambda d: (d.update(version=1), d["maps"].update(kd="../kd.exr")))
    assert "scene.json: maps.kd: expected a relative path" in one_error(scene_dir)


def test_missing_file(scene_dir):
    (scene_dir / "maps" / "kd.exr").unlink()
    msg = one_error(scene_dir)
    assert "scene.json: maps.kd:" in msg and str(scene_dir / "maps" / "kd.exr") in msg


def test_map_size_mismatch(scene_dir):
    write_exr(scene_dir / "maps" / "ks.exr", np.zeros((8, 10, 3), np.float32))
    msg = one_error(scene_dir)
    assert "ks.exr: maps.ks:" in msg and "map size mismatch" in msg and "8x10" in msg and "8x12" in msg


def test_nan_texel(scene_dir):
    kd = read_image(scene_dir / "maps" / "kd.exr")
    kd[3, 5, 1] = np.nan
    write_exr(scene_dir / "maps" / "kd.exr", kd)
    msg = one_error(scene_dir)
    assert "kd.exr: maps.kd: expected finite values, texel (row 3, col 5, channel G) is nan" in msg


def test_out_of_range_and_channels(scene_dir):
    ka = read_image(scene_dir / "maps" / "ka.exr")
    ka[2, 1] = 0.0
    write_exr(scene_dir / "maps" / "ka.exr", ka)
    assert "ka.exr: maps.ka: expected values in (0, 1], texel (row 2, col 1) is 0" in one_error(scene_dir)
    write_exr(scene_dir / "maps" / "ka.exr", np.full((8, 12, 3), 0.5, np.float32))
    assert "ka.exr: maps.ka: expected 1 channel(s) (Y), got 3" in one_error(scene_dir)


def test_kg_shape(scene_dir):
    write_exr(scene_dir / "maps" / "kg.exr", np.ones((20, 4, 3), np.float32))
    assert "kg.exr: maps.kg: expected a cube map of 6 N x N texels" in one_error(scene_dir)


def test_mesh_without_uvs(scene_dir):
    (scene_dir / "mesh.ply").unlink()
    (scene_dir / "plain.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    edit_json(scene_dir, lambda d: d.update(mesh="plain.obj"))
    msg = one_error(scene_dir)
    assert "plain.obj: vertex s,t (texture coordinates): expected" in msg


def test_unsupported_camera_model(scene_dir):
    path = scene_dir / "cameras" / "cameras.txt"
    text = path.read_text().replace(" PINHOLE ", " RADIAL ")
    path.write_text(text.replace("RADIAL 32 24 30 30 16 12", "RADIAL 32 24 30 16 12 0.1 0.01"))
    msg = one_error(scene_dir)
    assert "cameras.txt: camera 2 (image v1.png) model:" in msg and "RADIAL" in msg


def test_write_refuses_bad_scene_and_leaves_nothing(tmp_path):
    bad = make_scene()
    bad.maps.kw[0, 0] = 1.5
    with pytest.raises(SceneError, match=r"kw\.exr: maps\.kw: expected values in \[0, 1\]"):
        write_scene(tmp_path / "s", bad)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_no_partial_directory(tmp_path, monkeypatch):
    import invrender.scene.format as fmt

    write_scene(tmp_path / "s", make_scene(cameras=False), metadata={"run": 1})

    def crash(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(fmt, "write_colmap", crash)  # fails after mesh and maps are written
    with pytest.raises(OSError):
        write_scene(tmp_path / "s", make_scene(), metadata={"run": 2})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]
    assert read_scene_json(tmp_path / "s")["metadata"] == {"run": 1}  # the old scene, untouched
    with pytest.raises(OSError):
        write_scene(tmp_path / "new", make_scene())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]
