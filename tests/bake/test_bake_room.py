"""bake --room: the room stages' outputs (room_box, room_lights, room_objects, room_materials)
written as one v2 scene directory at the photo's camera."""

from __future__ import annotations

import json

import numpy as np
import pytest

from invrender.bake import room
from invrender.scene.format import load_scene, read_scene_json
from invrender.scene.room_scene import object_transform_of
from invrender.scene.types import SceneError

ROOM = {
    "box": {"center": [0.0, 1.25, 0.0], "size": [4.0, 2.5, 3.0], "yaw_deg": 0.0},
    "camera": {
        "width": 32,
        "height": 24,
        "params": [30.0, 30.0, 16.0, 12.0],
        "R": np.eye(3).tolist(),
        "t": [0.0, -1.2, 1.0],
    },
}
LIGHTS = {
    "lights": [
        {
            "kind": "ceiling",
            "name": "ceiling_0_0",
            "center": [0, 2.5, 0],
            "e1": [0.5, 0, 0],
            "e2": [0, 0, 0.5],
            "normal": [0, -1, 0],
            "radiance": [1.5, 1.5, 1.5],
        }
    ],
    "lamps": [],
}
CHAIR = {"name": "chair", "asset": "chair_a", "segment": 5, "position": [0.5, 0.0, -0.5], "yaw_deg": 10, "scale": 0.9}


def _stage_dirs(tmp_path):
    dirs = {name: tmp_path / name for name in ("room_box", "room_lights", "room_objects", "room_materials")}
    for d in dirs.values():
        d.mkdir()
    (dirs["room_box"] / "room.json").write_text(json.dumps(ROOM))
    (dirs["room_lights"] / "lights.json").write_text(json.dumps(LIGHTS))
    placed = {
        "name": "chair",
        "asset": "chair_a",
        "segment": 5,
        "T_obj2world": object_transform_of(CHAIR, "t").tolist(),
    }
    (dirs["room_objects"] / "objects.json").write_text(json.dumps({"objects": [placed]}))
    floor = {
        m: np.full((24, 32, 3) if m in ("kd", "ks", "ke") else (24, 32), v, np.float32)
        for m, v in (("kd", 0.2), ("ks", 0.04), ("ka", 0.3), ("ke", 0.0), ("kw", 0.0))
    }
    np.savez(dirs["room_materials"] / "floor.npz", **floor)
    materials = {
        "materials": {
            "wall": {"kd": [0.6, 0.5, 0.4]},
            "floor": {"atlas": "floor.npz"},
            "chair.seat": {"kd": [0.1, 0.2, 0.7], "ks": 0.1, "ka": 0.05},
        }
    }
    (dirs["room_materials"] / "materials.json").write_text(json.dumps(materials))
    return dirs


def test_the_room_stages_become_one_scene(tmp_path):
    dirs = _stage_dirs(tmp_path)
    meta = room.run(
        dirs["room_box"],
        tmp_path / "scene",
        dirs["room_lights"],
        dirs["room_objects"],
        dirs["room_materials"],
        texels_per_meter=8,
    )
    scene = load_scene(tmp_path / "scene")
    names = [o.name for o in scene.objects]
    assert names == ["wall_mx", "wall_px", "wall_mz", "wall_pz", "floor", "ceiling", "chair", "light_ceiling_0_0"]
    assert np.allclose(scene.cameras[0].params, ROOM["camera"]["params"]) and np.allclose(
        scene.cameras[0].t, [0, -1.2, 1]
    )
    sets = scene.packing.unpack_atlas(scene.maps)
    assert np.allclose(sets["wall_mz"].kd, [0.6, 0.5, 0.4]) and np.allclose(sets["floor"].kd, 0.2)
    assert sets["floor"].atlas_shape == (24, 32)  # 4 x 3 m at 8 texels per meter
    assert np.isclose(sets["chair"].kd[..., 2], 0.7).any() and np.isclose(sets["chair"].kd, 0.5).any()
    assert np.allclose(sets["light_ceiling_0_0"].ke, 1.5)
    chair = scene.objects[names.index("chair")]
    assert np.allclose(chair.transform, object_transform_of(CHAIR, "t"), atol=1e-6)
    doc = read_scene_json(tmp_path / "scene")["metadata"]
    assert doc["recovered_by"] == "invrender room_box + room_objects + room_lights + room_materials + bake"
    assert (
        [i["class"] for i in doc["instances"]][-2:]
        == ["object", "lamp"]
        == [i["class"] for i in meta["instances"]][-2:]
    )


def test_the_room_box_alone_is_an_empty_grey_room(tmp_path):
    dirs = _stage_dirs(tmp_path)
    room.run(dirs["room_box"], tmp_path / "scene", texels_per_meter=8)
    scene = load_scene(tmp_path / "scene")
    sets = scene.packing.unpack_atlas(scene.maps)
    assert len(scene.objects) == 6 and all(np.allclose(a.kd, 0.5) and np.allclose(a.ke, 0) for a in sets.values())


def test_missing_or_bad_inputs_are_one_scene_error(tmp_path):
    dirs = _stage_dirs(tmp_path)
    with pytest.raises(SceneError, match="room_box stage's room.json"):
        room.run(tmp_path / "nowhere", tmp_path / "scene")
    (dirs["room_materials"] / "floor.npz").unlink()
    with pytest.raises(SceneError, match="atlas"):
        room.run(dirs["room_box"], tmp_path / "scene", materials_dir=dirs["room_materials"])
    assert not (tmp_path / "scene").exists()


def test_the_room_scene_exports_to_usd_with_its_objects_and_camera(tmp_path):
    from pxr import Usd, UsdGeom, UsdLux

    from invrender.export import stage as export

    dirs = _stage_dirs(tmp_path)
    room.run(dirs["room_box"], tmp_path / "scene", dirs["room_lights"], dirs["room_objects"], texels_per_meter=8)
    export.run(tmp_path / "scene", tmp_path / "export")
    stage = Usd.Stage.Open(str(tmp_path / "export" / "scene.usda"))
    prims = list(stage.Traverse())
    objects = {p.GetParent().GetName() for p in prims if p.IsA(UsdGeom.Mesh)}
    assert {"wall_mx", "wall_px", "wall_mz", "wall_pz", "floor", "ceiling", "chair"} <= objects
    (camera,) = [p for p in prims if p.IsA(UsdGeom.Camera)]
    assert camera.GetName() == "photo"
    # the camera sits where room.json puts it: centre -R^T t = (0, 1.2, -1)
    world = UsdGeom.Xformable(camera).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    assert np.allclose(list(world.ExtractTranslation()), [0.0, 1.2, -1.0], atol=1e-5)
    assert any(p.HasAPI(UsdLux.MeshLightAPI) or p.IsA(UsdLux.RectLight) for p in prims)
