"""scene/room_scene.assemble_room: the room stages' outputs as one v2 scene.

The reference is independent of the assembly: the room generator's truth scene (one xatlas mesh
whose instance ids are the photo's segment ids, built by synthesize/room_photo.py) rendered at
the photo's camera. The assembled scene, fed the truth's box, objects and lights, must show each
class and each object at the same pixels."""

from __future__ import annotations

import numpy as np
import pytest

from invrender.assets.library import library
from invrender.scene.atlas import rasterize_atlas
from invrender.scene.format import load_scene, read_scene_json, write_scene
from invrender.scene.room_photo import ROOM_CLASSES
from invrender.scene.room_scene import (
    DEFAULT_MATERIAL,
    assemble_room,
    box_surfaces,
    object_transform_of,
    truth_lights,
)
from invrender.scene.types import Atlas, SceneError

BOX = {"center": [0.2, 1.25, -0.1], "size": [4.0, 2.5, 3.0], "yaw_deg": 20.0}
CAMERA = {"width": 8, "height": 6, "fov_y_deg": 60.0, "R": np.eye(3).tolist(), "t": [0.0, -1.2, 0.5]}


@pytest.fixture(scope="module")
def living():
    """The generator's living room at 128 x 96 (truth scene, metadata) and its ids render."""
    from invrender.synthesize.room_photo import make_room_photo

    scene, metadata = make_room_photo(
        {"layout": "living", "camera": {"width": 128, "height": 96}, "atlas_resolution": 256}
    )
    return scene, metadata


def _ids(scene):
    from invrender.render.analysis import analyse
    from invrender.render.renderer import Renderer

    (camera,) = scene.cameras
    return np.asarray(Renderer(scene, analyse(scene)).render(camera, spp=1, seed=0)["instance_id"])


def test_the_truth_assembled_covers_the_photo_as_the_truth_scene(living):
    truth_scene, metadata = living
    truth = metadata["room"]
    labels = {s["id"]: (s["class"], s["name"]) for s in metadata["segments"]}
    room = assemble_room(truth, truth["objects"], truth_lights(truth), assets=library(), labels=labels)
    reference, got = _ids(truth_scene), _ids(room)
    by_id = {i["instance_id"]: i for i in room.metadata["instances"]}
    truth_class = np.vectorize(lambda i: labels[int(i)][0] if int(i) in labels else "none")(reference)
    got_class = np.vectorize(lambda i: by_id[int(i)]["class"] if int(i) in by_id else "none")(got)
    assert (got_class == truth_class).mean() > 0.998  # measured 0.9995 at 160 x 120
    for cls in ROOM_CLASSES:
        a, b = truth_class == cls, got_class == cls
        assert a.sum() > 0, cls  # the living room's photo shows every class
        assert (a & b).sum() / (a | b).sum() > 0.95, cls  # lamps (a few pixels each): 0.96
    # Each object at its own segment's pixels: the placement (position, yaw, scale) is the truth's.
    for inst in room.metadata["instances"]:
        if inst["kind"] == "object":
            a, b = reference == inst["segment"], got == inst["instance_id"]
            assert (a & b).sum() / (a | b).sum() > 0.97, inst["name"]


def test_the_box_faces_into_the_room_with_uvs_in_meters():
    room = assemble_room({"box": BOX, "camera": CAMERA}, texels_per_meter=40)
    center = np.asarray(BOX["center"])
    names = [o.name for o in room.objects]
    assert names == ["wall_mx", "wall_px", "wall_mz", "wall_pz", "floor", "ceiling"]
    for obj in room.objects:
        p = obj.mesh.positions.astype(np.float64)[obj.mesh.faces]
        normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        assert np.all(np.einsum("fc,fc->f", normal, center - p.mean(axis=1)) > 0), obj.name  # front inwards
        # UVs span the quad; its set is 40 texels per meter along both edges.
        surface = room.metadata["surfaces"][obj.name]
        h, w = room.packing.rects[obj.name].height, room.packing.rects[obj.name].width
        assert (w, h) == tuple(round(40 * s) for s in surface["size"])
        origin, u, v = (np.asarray(surface[k]) for k in ("origin", "u_axis", "v_axis"))
        meters = (obj.mesh.positions - origin) @ np.stack([u, v], axis=1)
        assert np.allclose(meters, obj.mesh.uvs * surface["size"], atol=1e-5)
    sizes = {s["name"]: s for s in box_surfaces({"box": BOX})}
    assert np.isclose(np.linalg.norm(sizes["wall_px"]["e1"]), 3.0) and np.isclose(
        np.linalg.norm(sizes["floor"]["e1"]), 4.0
    )


def test_materials_lights_and_lamps():
    asset = next(a for a in library() if a.emissive_parts)
    obj = {"name": "lamp", "asset": asset.name, "segment": 9, "position": [0.5, 0, 0], "yaw_deg": 30, "scale": 1.2}
    lights = {
        "lights": [
            {
                "kind": "ceiling",
                "name": "c",
                "center": [0, 2.5, 0],
                "e1": [0.4, 0, 0],
                "e2": [0, 0, 0.4],
                "normal": [0, -1, 0],
                "radiance": [2.0, 2.0, 2.0],
            },
            {
                "kind": "window",
                "name": "window",
                "center": [0, 1.2, -1.6],
                "e1": [1, 0, 0],
                "e2": [0, 1, 0],
                "normal": [0, 0, 1],
                "radiance": [3.0, 3.0, 3.0],
            },
        ],
        "lamps": [{"segment": 9, "radiance": [5.0, 5.0, 5.0]}],
    }
    floor = Atlas.uniform((120, 160), kd=0.3)
    materials = {"wall": {"kd": [0.7, 0.6, 0.5]}, "floor": floor, f"lamp.{asset.part_names[0]}": {"ks": 0.2}}
    room = assemble_room(
        {"box": {**BOX, "yaw_deg": 0.0}, "camera": CAMERA}, [obj], lights, materials, library(), texels_per_meter=40
    )
    sets = room.packing.unpack_atlas(room.maps)
    assert np.allclose(sets["wall_pz"].kd, [0.7, 0.6, 0.5]) and np.allclose(sets["ceiling"].kd, DEFAULT_MATERIAL["kd"])
    assert np.array_equal(sets["floor"].kd, floor.kd)
    by_name = {i["name"]: i for i in room.metadata["instances"]}
    assert by_name["lamp"]["class"] == "lamp" and by_name["light_window"]["class"] == "window"
    assert by_name["light_c"]["class"] == "lamp" and by_name["light_c"]["kind"] == "light"
    assert np.allclose(sets["light_window"].ke, 3.0) and np.allclose(sets["light_c"].kd, 0.0)
    # Lights are one-sided and lie inset off their wall or ceiling (1e-3 box heights).
    lamp_faces = np.flatnonzero(room.mesh.instance_ids == by_name["light_c"]["instance_id"])
    assert room.mesh.one_sided[lamp_faces].all() and not room.mesh.one_sided[room.mesh.instance_ids == 1].any()
    assert np.allclose(room.mesh.positions[room.mesh.faces[lamp_faces]][..., 1], 2.5 - 2.5e-3)
    # The lamp's shade emits its radiance; its first part carries the given ks.
    lamp = next(o for o in room.objects if o.name == "lamp")
    ranges = room.metadata["parts"]["lamp"]
    texel_rows = {}
    texels = rasterize_atlas(lamp.mesh, *sets["lamp"].atlas_shape)
    for part, (start, stop) in ranges.items():
        texel_rows[part] = (texels.triangle >= start) & (texels.triangle < stop)
    for part in asset.emissive_parts:
        assert np.allclose(sets["lamp"].ke[texel_rows[part]], 5.0)
    first = asset.part_names[0]
    assert np.allclose(sets["lamp"].ks[texel_rows[first]], 0.2)
    assert np.allclose(lamp.transform, object_transform_of(obj, "t"))


def test_a_placement_matrix_is_the_generators_position_yaw_and_scale():
    placed = {"position": [0.4, 0.7, -1.0], "yaw_deg": 35.0, "scale": 1.5}
    T = object_transform_of(placed, "t")
    assert np.allclose(object_transform_of({"T_obj2world": T.tolist()}, "t"), T)
    a = np.radians(35.0)
    assert np.allclose(T[:3, 0], 1.5 * np.array([np.cos(a), 0, -np.sin(a)])) and np.allclose(
        T[:3, 3], placed["position"]
    )


def test_it_writes_and_loads_as_a_v2_scene(tmp_path):
    room = assemble_room({"box": BOX, "camera": CAMERA}, lights=truth_lights({"box": BOX, "lights": []}))
    write_scene(tmp_path / "scene", room, room.metadata)
    loaded = load_scene(tmp_path / "scene")
    assert [o.name for o in loaded.objects] == [o.name for o in room.objects]
    assert np.allclose(loaded.cameras[0].params, room.cameras[0].params)
    assert read_scene_json(tmp_path / "scene")["metadata"]["instances"][0]["class"] == "wall"


@pytest.mark.parametrize(
    "objects, materials, field",
    [
        ([{"asset": "no_such_chair", "position": [0, 0, 0], "scale": 1}], None, "objects[0].asset"),
        ([{"asset": "chair_a", "position": [0, 0, 0]}], None, "T_obj2world"),
        ([{"asset": "chair_a", "T_obj2world": np.diag([1, 1, -1, 1]).tolist()}], None, "T_obj2world"),
        ([], {"floor": Atlas.uniform((3, 3))}, "materials['floor']"),
    ],
)
def test_bad_input_is_one_scene_error(objects, materials, field):
    with pytest.raises(SceneError) as error:
        assemble_room({"box": BOX, "camera": CAMERA}, objects, None, materials, library())
    assert field in error.value.field
