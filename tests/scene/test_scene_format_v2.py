"""Scene format version 2 on disk: objects, material sets, instances; v1 still loads as before."""

import json

import numpy as np
import pytest
from testscenes import three_objects

from invrender.scene.format import load_scene, write_scene
from invrender.scene.images import write_exr
from invrender.scene.packing import pack_scene
from invrender.scene.types import SceneError


@pytest.fixture()
def v2_dir(tmp_path):
    objects, materials, kg, cameras = three_objects()
    objects[1].emission_sides = "one"
    write_scene(tmp_path / "scene", pack_scene(objects, materials, kg, cameras), metadata={"by": "test"})
    return tmp_path / "scene"


def _edit(directory, change):
    path = directory / "scene.json"
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


def _error(directory) -> str:
    with pytest.raises(SceneError) as err:
        load_scene(directory)
    return str(err.value)


def test_v2_round_trip_keeps_objects_sets_and_instances(v2_dir):
    objects, materials, kg, _ = three_objects()
    doc = json.loads((v2_dir / "scene.json").read_text())
    assert doc["version"] == 2 and sorted(doc["materials"]) == ["paint", "walls", "wood"]
    assert [o["mesh"] for o in doc["objects"]] == [
        "meshes/room.ply",
        "meshes/table.ply",
        "meshes/cube_a.ply",
        "meshes/cube_a.ply",
    ]  # the cube is written once
    assert sorted(p.name for p in (v2_dir / "meshes").iterdir()) == ["cube_a.ply", "room.ply", "table.ply"]
    scene = load_scene(v2_dir)
    assert scene.objects[2].mesh is scene.objects[3].mesh
    for got, want in zip(scene.objects, objects):
        assert (got.name, got.material, got.instance_id) == (want.name, want.material, want.instance_id)
        assert np.array_equal(got.transform, want.transform)  # JSON keeps float64 exactly
        assert np.array_equal(got.mesh.positions, want.mesh.positions) and np.array_equal(got.mesh.uvs, want.mesh.uvs)
    assert [o.emission_sides for o in scene.objects] == ["two", "one", "two", "two"]
    for name, atlas in scene.packing.unpack_atlas(scene.maps).items():
        for m in ("kd", "ks", "ka", "ke", "kw"):
            assert np.array_equal(getattr(atlas, m), getattr(materials[name], m)), (name, m)
    assert np.array_equal(scene.maps.kg, kg)
    assert np.all(scene.mesh.one_sided[14:16]) and scene.mesh.one_sided.sum() == 2  # the table's; the room has 14


def test_write_writes_what_the_renderer_renders(v2_dir, tmp_path):
    """An optimiser changes the packed maps: write_scene writes them, cut back into the sets."""
    scene = load_scene(v2_dir)
    r = scene.packing.rects["wood"]
    scene.maps.kd[r.row, r.col] = [0.25, 0.5, 0.75]
    write_scene(tmp_path / "again", scene)
    assert np.array_equal(
        load_scene(tmp_path / "again").packing.unpack_atlas(scene.maps)["wood"].kd[0, 0], np.float32([0.25, 0.5, 0.75])
    )


def test_a_v1_scene_still_loads_and_writes_as_v1(tmp_path):
    from testscenes import box_room

    write_scene(tmp_path / "v1", box_room())
    scene = load_scene(tmp_path / "v1")
    assert scene.version == 1 and scene.objects == [] and scene.packing is None
    assert json.loads((tmp_path / "v1" / "scene.json").read_text())["version"] == 1


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d["objects"][0].update(material="stone"), "objects[0].material: expected one of the material sets"),
        (lambda d: d["objects"][1].update(name="room"), "objects[1].name: expected a name no other object has"),
        (
            lambda d: d["objects"][0].update(transform=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]),
            "objects[0].transform: expected a transform that keeps orientation",
        ),
        (
            lambda d: d["objects"][0].update(transform=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
            "objects[0].transform: expected",
        ),
        (lambda d: d["objects"][0].update(emission_sides="front"), "objects[0].emission_sides: expected one of"),
        (lambda d: d["materials"]["wood"].pop("ka"), "materials.wood.ka: expected this required field"),
        (lambda d: d["objects"][0].update(mesh="../room.ply"), "objects[0].mesh: expected a relative path"),
        (lambda d: d["objects"][0].update(mesh="meshes/none.ply"), "objects[0].mesh: expected an existing file"),
        (lambda d: d.pop("kg"), "kg: expected this required field"),
        (lambda d: d.update(objects=[]), "objects: expected"),
    ],
)
def test_bad_v2_documents_are_one_error_naming_the_field(v2_dir, change, message):
    _edit(v2_dir, change)
    assert message in _error(v2_dir)


def test_bad_material_map_names_its_set(v2_dir):
    write_exr(v2_dir / "materials" / "paint" / "ks.exr", np.zeros((3, 3, 3), np.float32))
    msg = _error(v2_dir)
    assert "ks.exr: materials.paint.ks: expected the size of materials.paint.kd" in msg
    write_exr(v2_dir / "materials" / "paint" / "ks.exr", np.full((2, 3, 3), 2.0, np.float32))
    assert "materials.paint.ks: expected values in [0, 1]" in _error(v2_dir)


def test_the_examples_in_docs_scene_format_are_valid_scene_json():
    import re
    from pathlib import Path

    from invrender.scene.format import validate_scene_json

    page = Path(__file__).resolve().parents[2] / "docs" / "scene-format.md"
    examples = [json.loads(block) for block in re.findall(r"```json\n(.*?)```", page.read_text(), re.S)]
    assert [doc["version"] for doc in examples] == [1, 2, 2]
    for doc in examples:
        validate_scene_json(doc, page)
